"""The page of `vmap view` at 100, 10,000 and 100,000 key images (examples/results/view.md).

For each memory bench_view makes (a real memory repeated as sessions, as bench_fleet makes
its synthetic memories: rtabmap_loop, whose page is a time line with its loop edges as
arcs, or tum_fr3_cabinet_kf with its poses, a map from above; examples/bench/bench_view.cpp),
in one run:

  read:   `vmap memory info M`, the time to open and read the memory (the baseline: what
          any command on the memory costs before its own work);
  write:  `vmap view M --out DIR --image-side 0` (the page without images) and, up to
          --images-up-to key images, `vmap view M --out DIR` (every key image read again
          from the seed's recorded input and written), wall time of the whole command;
  size:   the page folder's bytes, per key image;
  open:   headless Chromium (Debian's chromium and chromium-driver through python3-selenium)
          loads DIR/index.html until the page says it is ready (everything drawn), then a
          click on a key image's mark until the key panel shows it (its image loaded, on a
          page with images): the time a user waits.

  python3 examples/bench/bench_view.py --bench build/release/examples/bench_view \\
      --vmap build/release/examples/vmap --shared ../shared [--seed rtabmap|cabinet]
"""

import argparse
import json
import os
import pathlib
import shutil
import subprocess
import sys
import time


def wall(*args):
    t0 = time.perf_counter()
    r = subprocess.run(list(map(str, args)), capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"bench_view: {' '.join(map(str, args))} failed:\n{r.stderr}")
    return time.perf_counter() - t0, r.stdout


def folder_bytes(folder):
    return sum(f.stat().st_size for f in pathlib.Path(folder).rglob("*") if f.is_file())


def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    o = Options()
    o.binary_location = "/usr/bin/chromium"
    for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--window-size=1100,900"):
        o.add_argument(a)
    return webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=o)


def open_and_click(driver, page, with_image):
    """Seconds until the page is ready, and from a click on a mark until the key panel shows it."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.support.ui import WebDriverWait

    driver.get("about:blank")
    t0 = time.perf_counter()
    driver.get((pathlib.Path(page) / "index.html").resolve().as_uri())
    WebDriverWait(driver, 120, poll_frequency=0.01).until(
        lambda d: d.execute_script("return !!(window.vmapView && window.vmapView.ready)"))
    opened = time.perf_counter() - t0
    n = driver.execute_script("return window.vmapView.keys")
    k = n // 2
    canvas = driver.find_element("id", "map")
    at = driver.execute_script(f"return window.vmapView.screenOf({k})")
    w, h = canvas.size["width"], canvas.size["height"]
    # The mark nearest the click is selected (marks of a large memory lie on one another).
    t1 = time.perf_counter()
    ActionChains(driver).move_to_element_with_offset(canvas, round(at["x"] - w / 2), round(at["y"] - h / 2)).click().perform()
    wait = ("const i = document.getElementById('key-image'); return window.vmapView.selected !== null && !!i && "
            "i.complete && i.naturalWidth > 0") if with_image else "return window.vmapView.selected !== null"
    WebDriverWait(driver, 60, poll_frequency=0.01).until(lambda d: d.execute_script(wait))
    clicked = time.perf_counter() - t1
    marks = driver.execute_script("return window.vmapView.marks")
    assert marks == n, (marks, n)
    return opened, clicked


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--bench", default="build/release/examples/bench_view", help="the bench_view program")
    p.add_argument("--vmap", default="build/release/examples/vmap", help="the vmap command line")
    p.add_argument("--shared", default="../shared")
    p.add_argument("--work", default="build/bench_view")
    p.add_argument("--sizes", default="100,10000,100000")
    p.add_argument("--seed", default="rtabmap", choices=["rtabmap", "cabinet"])
    p.add_argument("--images-up-to", type=int, default=10000, help="pages with images for memories up to this size")
    p.add_argument("--rounds", type=int, default=3, help="browser openings per page (the fastest and slowest are shown)")
    a = p.parse_args()
    _, out = wall(a.bench, "--shared", a.shared, "--work", a.work, "--sizes", a.sizes, "--seed", a.seed)
    memories = [line.split()[1:] for line in out.splitlines() if line.startswith("memory ")]
    driver = browser()
    rows = []
    try:
        for size, path, keys, loops in memories:
            keys, loops = int(keys), int(loops)
            read, _ = wall(a.vmap, "memory", "info", path)
            pages = [("no images", ["--image-side", "0"], False)]
            if keys <= a.images_up_to:
                pages.append(("images", [], True))
            for label, extra, with_image in pages:
                page = pathlib.Path(a.work) / f"page_{a.seed}_{size}_{'images' if with_image else 'data'}"
                if page.exists():
                    shutil.rmtree(page)
                write, stdout = wall(a.vmap, "view", path, "--out", page, "--json", *extra)
                result = json.loads(stdout)
                size_bytes = folder_bytes(page)
                opens, clicks = [], []
                for _ in range(a.rounds):
                    o, c = open_and_click(driver, page, with_image and result["images"] > 0)
                    opens.append(o)
                    clicks.append(c)
                rows.append((keys, loops, label, read, write, result, size_bytes, opens, clicks))
                print(f"bench_view: {keys} key images, {label}: write {write:.2f} s, open {min(opens):.2f} s, "
                      f"click {min(clicks):.2f} s", file=sys.stderr, flush=True)
    finally:
        driver.quit()
    print("| key images | loop edges (matches drawn) | page | read the memory (`memory info`), s | write the page "
          "(`vmap view`), s | write / read | folder, MB | bytes per key image | open in Chromium, s | click to key "
          "image shown, s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for keys, loops, label, read, write, r, size_bytes, opens, clicks in rows:
        print(f"| {keys} | {loops} ({r['matched_loops']}) | {label} ({r['images']} images) | {read:.2f} | {write:.2f} | "
              f"{write / read:.1f} | {size_bytes / 1e6:.1f} | {size_bytes / keys:.0f} | "
              f"{min(opens):.2f}-{max(opens):.2f} | {min(clicks):.2f}-{max(clicks):.2f} |")


if __name__ == "__main__":
    main()
