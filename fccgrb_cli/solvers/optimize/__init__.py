"""Frames through the optimization methods (CNO and goal attainment): one frame's problem, the
loop over frames (sequential or parallel) and its compiled twin."""
