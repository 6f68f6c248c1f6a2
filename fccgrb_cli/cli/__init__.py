"""The command line (``fccgrb``): thin commands over the pipeline, batch and presentation."""
