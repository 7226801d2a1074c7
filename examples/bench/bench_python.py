"""The Python module's overhead against the same work in C++, in one run (examples/python.md).

push per frame: the same frames pushed into a memory with the same policy stack (ORB
1000, MAGSAC++), timed around each push: from Python (vmap.VisualMemory.push, one call
per frame, the image a NumPy array read in place) and in C++ (`vmap memory build --json`,
whose "seconds" are its pushes alone, without decoding or syncing).

localize per query: the same query images localized in the same memory, timed around
each call: from Python (VisualMemory.localize) and in C++ (`vmap memory localize --json`,
whose "ms" per query is the call alone, the image decoded before).

Both sides must give the same key images and the same answers, or the figures are not
printed. Each figure is the fastest of --rounds rounds, the two sides alternating, so a
busy moment of a shared machine does not land on one side only.
"""

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import vmap


def run_json(*args):
    return json.loads(subprocess.run(list(args), check=True, capture_output=True, text=True).stdout)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--source", default="../shared/data/tum_fr1_rpy/rgb.txt", help="frames (a TUM rgb.txt, folder, video)")
    p.add_argument("--vmap", default="build/release/examples/vmap", help="the vmap command line")
    p.add_argument("--frames", type=int, default=400, help="frames pushed into the memory")
    p.add_argument("--queries", type=int, default=50, help="frames after them localized")
    p.add_argument("--rounds", type=int, default=3)
    a = p.parse_args()
    if not pathlib.Path(a.source).exists():
        sys.exit(f"bench_python: {a.source} not found (give --source)")

    frames = list(vmap.frames(a.source, grey=True, end=a.frames))
    queries = list(vmap.frames(a.source, grey=True, start=a.frames, end=a.frames + a.queries))
    # Zero copies: the arrays vmap.frames gives view the decoded frames, and push reads
    # each array's own buffer.
    views = sum(not img.flags.owndata for img, _, _ in frames)
    in_place = sum(vmap.image_address(img) == img.ctypes.data for img, _, _ in frames)
    folder = pathlib.Path(a.source).resolve().parent
    query_files = [str(folder / "rgb" / name) for _, _, name in queries]
    if not all(os.path.exists(f) for f in query_files):
        sys.exit("bench_python: the localize half needs a TUM-layout source (rgb/<name> beside the list)")

    best = {"py_push": float("inf"), "cpp_push": float("inf"), "py_loc": float("inf"), "cpp_loc": float("inf")}
    with tempfile.TemporaryDirectory() as tmp:
        store = os.path.join(tmp, "cpp.vmdb")
        for r in range(a.rounds):
            built = run_json(a.vmap, "memory", "build", a.source, "--end", str(a.frames), "--memory", store,
                             "--force", "--json")
            best["cpp_push"] = min(best["cpp_push"], built["seconds"])

            mem = vmap.VisualMemory()
            total = 0.0
            for img, t, name in frames:
                t0 = time.perf_counter()
                mem.push(img, timestamp=t, name=name)
                total += time.perf_counter() - t0
            best["py_push"] = min(best["py_push"], total)
            info = run_json(a.vmap, "memory", "info", store, "--json")
            if [k["frame_index"] for k in info["key_images"]] != [k["frame_index"] for k in mem.keys]:
                sys.exit("bench_python: Python and C++ chose different key images; no figure printed")

            answers = run_json(a.vmap, "memory", "localize", store, *query_files, "--json")["queries"]
            best["cpp_loc"] = min(best["cpp_loc"], sum(q["ms"] for q in answers) / 1000.0)
            reader = vmap.VisualMemory.open(store, read_only=True)
            total = 0.0
            for (img, _, _), answer in zip(queries, answers):
                t0 = time.perf_counter()
                got = reader.localize(img)
                total += time.perf_counter() - t0
                if got.status != answer["status"] or got.key != answer["key"]:
                    sys.exit("bench_python: Python and C++ localized a query differently; no figure printed")
            best["py_loc"] = min(best["py_loc"], total)
            print(f"round {r + 1} of {a.rounds} done", file=sys.stderr)

    n, q = len(frames), len(queries)
    print(f"{n} frames ({mem.key_images} key images), {q} queries, {a.source}; fastest of {a.rounds} rounds")
    print(f"images: {views} of {n} frames are views of the decoded frame, {in_place} of {n} read in place by push")
    print(f"{'':22} {'C++':>10} {'Python':>10} {'overhead':>9}")
    for label, py, cpp, count in (("push per frame (ms)", "py_push", "cpp_push", n),
                                  ("localize per query (ms)", "py_loc", "cpp_loc", q)):
        c, y = best[cpp] / count * 1000, best[py] / count * 1000
        print(f"{label:22} {c:10.3f} {y:10.3f} {100 * (y / c - 1):8.1f}%")


if __name__ == "__main__":
    main()
