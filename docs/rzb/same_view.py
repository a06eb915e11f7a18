#!/usr/bin/env python3
"""Writes a camera path of a scene's default camera repeated N times (Table 1: the first frame
renders a new sample set, the later ones sample from the caches it filled).

    ./target/release/occult info --json SCENE | python3 docs/rzb/same_view.py N > path.json
"""
import json
import sys

camera = json.load(sys.stdin)["default_camera"]
print("[\n" + ",\n".join(json.dumps(camera) for _ in range(int(sys.argv[1]))) + "\n]")
