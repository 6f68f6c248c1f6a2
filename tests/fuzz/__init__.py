"""Generated bad input for the whole command line, run as real ``fccgrb`` processes.

Every case is a command (or a short chain of commands) in a fresh folder holding a small set of
good files (``fixtures``) and whatever damaged file the case adds: a C3D with a patched header
word or parameter, a TRC header that lies, a YAML bomb, a FIFO where a file should be, a number
no option accepts, an output that is one of the command's own inputs, a results file with a
hole in it. ``runner`` runs it in a subprocess and checks what the README promises: no
traceback, exit status 2 (never 0) on bad input with one ``fccgrb: error:`` line naming the file,
key path or option, no file left behind, no input changed, no hang.

    python -m tests.fuzz --all              # every case (≥ 300), two at a time
    python -m tests.fuzz --seed 7 --all     # another draw of the random patches and values
    python -m pytest tests/test_fuzz.py     # the seeded subset the default suite runs
"""
