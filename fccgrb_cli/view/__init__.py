"""The 3D view (presentation layer: it reads results and model files, nothing imports it):
``fccgrb view RESULTS.h5 -o motion.html``, ``fccgrb view MODEL.yaml -o model.html`` and still
SVG pictures of one frame. See docs/view.md."""
