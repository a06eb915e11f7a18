#!/usr/bin/env python3
"""Writes a slow camera path for Fig. 8 (sample caching on a walkthrough, Wand et al. 2001 §8.5):
`frames` views moving `step` metres each along +z at the forest's canopy height, looking ahead
and down like the forest's default camera, repeated `passes` times (the second pass replays the
first with the caches filled).

    python3 docs/rzb/slow_walk.py FRAMES STEP PASSES > path.json
"""
import json
import sys

frames, step, passes = int(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3])
# The default camera of `forest` (occult info forest:replicate=9): above the centre, just over
# the tallest tree, looking towards +z and down at the canopy.
eye = [-0.13, 32.91, -0.21]
ahead = [0.0, -27.91, 120.0]
views = []
for _ in range(passes):
    for k in range(frames):
        e = [eye[0], eye[1], round(eye[2] + k * step, 3)]
        t = [round(e[i] + ahead[i], 3) for i in range(3)]
        views.append({"eye": e, "target": t, "fov_y_deg": 60.0, "near": 0.5})
print("[\n" + ",\n".join(json.dumps(v) for v in views) + "\n]")
