#!/usr/bin/env python3
"""Loop edges of a vmap memory store between two parts of a sequence, read without vmap.

    python3 examples/loops_between.py MEMORY.vmdb GT_MATRIX SPLIT

Reads the store with Python's sqlite3 module only (the schema is in examples/memory.md,
"The memory store") and an N x N 0/1 ground-truth loop matrix over the sequence's frames
(rtabmap_loop's gt_loop_matrix_84x84.txt). Queries are the key images of frames >= SPLIT
whose frame the matrix marks as a revisit of a frame < SPLIT; a query is found when one
of its loop edges goes to a key image of a frame < SPLIT that the matrix marks. Prints
the recall over those queries and how many edges into frames < SPLIT the matrix marks.
"""
import sqlite3
import sys


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    memory, matrix, split = sys.argv[1], sys.argv[2], int(sys.argv[3])
    with open(matrix) as f:
        gt = [[int(v) for v in line.split()] for line in f if line.strip()]
    db = sqlite3.connect("file:" + memory + "?mode=ro", uri=True)
    frame = dict(db.execute("SELECT id, frame_index FROM key_images"))
    session = {}
    starts = db.execute("SELECT id, first_key FROM sessions ORDER BY id").fetchall()
    for key in frame:
        session[key] = max(s for s, first in starts if first <= key)
    edges = db.execute("SELECT from_key, to_key FROM loops").fetchall()

    def marked(a, b):
        return a < len(gt) and b < len(gt[a]) and gt[a][b] != 0

    queries = [k for k, f in frame.items() if f >= split and any(marked(f, j) for j in range(split))]
    into = [(a, b) for a, b in edges if frame[a] >= split and frame[b] < split]
    true = [(a, b) for a, b in into if marked(frame[a], frame[b])]
    found = {a for a, _ in true}
    across = sum(1 for a, b in edges if session[a] != session[b])
    recall = len(found & set(queries)) / len(queries) if queries else 0.0
    print(f"{memory}: {len(starts)} sessions, {len(frame)} key images, {len(edges)} loop edges ({across} across "
          f"sessions); {len(queries)} key images of frames >= {split} revisit frames < {split}, "
          f"{len(found & set(queries))} found (recall {recall:.3f}); {len(into)} edges into frames < {split}, "
          f"{len(true)} marked by the ground truth")


if __name__ == "__main__":
    main()
