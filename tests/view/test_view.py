"""`vmap view` and memory.view() in a real browser (headless Chromium): the page loads with
no console error, holds one mark per key image and one line per loop edge, shows a key
image on click, places the answers of `vmap localize --json` on their key images (with
the metric pose where an answer has one), draws the time line without poses and the map
from above with them, shows each robot of a fleet, and is never written for a missing or
damaged memory."""

import json
import os
import pathlib


from conftest import console_errors, fresh, hook, open_page, run_vmap

REPO = pathlib.Path(__file__).resolve().parents[2]
SAMPLE = REPO / "examples" / "data" / "tum_fr1_rpy_60"


def click_key(browser, k):
    """Clicks key image k's mark on the map canvas, as a user does."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.support.ui import WebDriverWait

    canvas = browser.find_element("id", "map")
    at = hook(browser, f"screenOf({k})")
    w, h = canvas.size["width"], canvas.size["height"]
    dx, dy = round(at["x"] - w / 2), round(at["y"] - h / 2)  # from the canvas's centre
    ActionChains(browser).move_to_element_with_offset(canvas, dx, dy).click().perform()
    WebDriverWait(browser, 5).until(lambda d: hook(d, "selected") is not None)


def wait_image(browser):
    from selenium.webdriver.support.ui import WebDriverWait

    WebDriverWait(browser, 10).until(lambda d: d.execute_script(
        "const i = document.getElementById('key-image'); return !!i && i.complete && i.naturalWidth > 0"))


def test_two_runs_time_line(browser, vmap_cli, two_runs, work):
    """No poses: the time line, one mark per key image and one arc per loop edge; a click on
    a mark shows that key image's image (read again from the recorded input) and its
    loops' verified matches."""
    memory, info = two_runs
    page = fresh(work / "page_two_runs")
    out = json.loads(run_vmap(vmap_cli, "view", memory, "--out", page, "--json").stdout)
    keys, loops = len(info["key_images"]), len(info["loops"])
    assert (out["key_images"], out["loops"], out["runs"], out["posed"]) == (keys, loops, 2, False)
    assert out["images"] == keys, out["images_from"]  # every frame read again from rgb.txt
    assert out["matched_loops"] == loops
    assert (page / "index.html").is_file() and (page / "data.js").is_file() and (page / "view.js").is_file()
    # Nothing the page loads is outside its folder, and nothing comes from the network.
    html = (page / "index.html").read_text()
    assert "http://" not in html and "https://" not in html
    open_page(browser, page)
    assert console_errors(browser) == []
    assert hook(browser, "mode") == "line"
    assert hook(browser, "marks") == keys
    assert hook(browser, "lines") == loops
    # A key image that closes a loop, clicked on the canvas.
    k = info["loops"][0]["from"]
    click_key(browser, k)
    assert hook(browser, "selected") == k
    wait_image(browser)
    from selenium.webdriver.support.ui import WebDriverWait

    WebDriverWait(browser, 10).until(lambda d: hook(d, "pair") is not None)
    pair = hook(browser, "pair")
    loop = info["loops"][pair["loop"]]  # the page's loops are the memory's, in order
    assert k in (loop["from"], loop["to"])
    # The matches drawn are the loop's verified inliers, found again by the same stack.
    assert pair["matches"] == loop["inliers"]
    # The loops' table sorts by confidence.
    browser.execute_script("window.vmapView.sortLoops('confidence')")
    cells = browser.execute_script(
        "return [...document.querySelectorAll('#loops tr.row')].map(r => parseFloat(r.children[5].textContent))")
    assert cells == sorted(cells, reverse=True) and len(cells) == min(loops, 200)
    assert console_errors(browser) == []


def test_screenshot_is_not_blank(browser, vmap_cli, two_runs, work):
    """The README's picture (examples/images/view.png): the sample mapped twice, a key image
    with loops clicked. The map canvas has drawn pixels (marks and arcs), not only its
    background."""
    import base64

    from selenium.webdriver.support.ui import WebDriverWait

    memory, info = two_runs
    page = fresh(work / "page_readme")
    run_vmap(vmap_cli, "view", memory, "--out", page, "--title", "tum_fr1_rpy_60 mapped twice")
    browser.set_window_size(1000, 900)
    try:
        open_page(browser, page)
        click_key(browser, info["loops"][0]["from"])
        wait_image(browser)
        WebDriverWait(browser, 10).until(lambda d: hook(d, "pair") is not None)
        pixels = hook(browser, "mapPixels()")
        size = browser.execute_script("const c = document.getElementById('map'); return c.width * c.height")
        assert pixels > 0.002 * size, f"{pixels} drawn pixels of {size}"
        assert console_errors(browser) == []
        # The top of the page at 3/4 scale: the summary, the map, the key image and a loop.
        shot = browser.execute_cdp_cmd("Page.captureScreenshot", {
            "format": "png", "captureBeyondViewport": True,
            "clip": {"x": 0, "y": 0, "width": 1000, "height": 760, "scale": 0.75}})
        png = base64.b64decode(shot["data"])
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10000
        out = pathlib.Path(os.environ.get("VMAP_VIEW_SCREENSHOT", str(work / "view.png")))
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_bytes(png)
    finally:
        browser.set_window_size(1100, 900)


def test_posed_map_from_above(browser, vmap_cli, posed, work):
    """Poses of known geometry (circles in the x-z plane, +y up): the page draws the map
    from above with +y up, one mark per key image and one line per loop edge."""
    memory, info = posed
    page = fresh(work / "page_posed")
    out = json.loads(run_vmap(vmap_cli, "view", memory, "--out", page, "--json").stdout)
    assert out["posed"] is True
    open_page(browser, page)
    assert console_errors(browser) == []
    assert hook(browser, "mode") == "map"
    assert hook(browser, "up") == "+y"
    assert hook(browser, "marks") == len(info["key_images"])
    assert hook(browser, "lines") == len(info["loops"])
    # Seen from above (+y toward the viewer): right is +z, top is +x; the two runs' circles
    # are 0.5 m apart along x, so the second run's marks sit higher on the page.
    ys = browser.execute_script(
        "const v = window.vmapView, D = window.VMAP_VIEW; const out = [0, 0]; const c = [0, 0];"
        "for (let k = 0; k < D.keys.n; k++) { out[D.keys.run[k]] += v.screenOf(k).y; c[D.keys.run[k]]++; }"
        "return [out[0] / c[0], out[1] / c[1]]")
    assert ys[1] < ys[0]
    # The time line of the same memory is one click away.
    browser.find_element("id", "mode-line").click()
    assert hook(browser, "mode") == "line" and hook(browser, "marks") == len(info["key_images"])


def test_real_poses(browser, vmap_cli, shared, work):
    """tum_fr3_cabinet_kf with its ground truth poses (the camera circles a cabinet at a
    height that stays within centimetres): the map from above with the motion capture's
    +z up, one mark per key image, one line per loop edge."""
    data = shared / "data" / "tum_fr3_cabinet_kf"
    memory = work / "cabinet.vmdb"
    run_vmap(vmap_cli, "build", data / "rgb.txt", "--memory", memory, "--force", "--poses",
             data / "truth_cam_poses.txt")
    info = json.loads(run_vmap(vmap_cli, "memory", "info", memory, "--json").stdout)
    page = fresh(work / "page_cabinet")
    out = json.loads(run_vmap(vmap_cli, "view", memory, "--out", page, "--json").stdout)
    assert out["posed"] and out["images"] == len(info["key_images"])
    open_page(browser, page)
    assert console_errors(browser) == []
    assert hook(browser, "up") == "+z"
    assert hook(browser, "marks") == len(info["key_images"]) and hook(browser, "lines") == len(info["loops"])
    click_key(browser, len(info["key_images"]) // 2)
    wait_image(browser)


def test_real_loops(browser, vmap_cli, shared, work):
    """rtabmap_loop (a robot drives a corridor loop twice): every loop edge drawn, and each
    loop's matches drawn are its stored inliers, found again by the memory's stack."""
    memory = work / "rtabmap.vmdb"
    run_vmap(vmap_cli, "build", shared / "data" / "rtabmap_loop" / "images", "--memory", memory, "--force")
    info = json.loads(run_vmap(vmap_cli, "memory", "info", memory, "--json").stdout)
    assert len(info["loops"]) > 10
    page = fresh(work / "page_rtabmap")
    out = json.loads(run_vmap(vmap_cli, "view", memory, "--out", page, "--json").stdout)
    assert out["matched_loops"] == len(info["loops"])
    open_page(browser, page)
    assert console_errors(browser) == []
    assert hook(browser, "lines") == len(info["loops"])
    from selenium.webdriver.support.ui import WebDriverWait

    for loop in info["loops"][:5]:
        browser.execute_script("window.vmapView.pair = null")
        browser.execute_script(f"window.vmapView.select({loop['from']})")
        WebDriverWait(browser, 10).until(lambda d: hook(d, "pair") is not None)
        pair = hook(browser, "pair")
        assert pair["matches"] == info["loops"][pair["loop"]]["inliers"]


def queries(sample_list, work):
    """Query images: three sample frames (their places are in the memory) and an image of
    noise (a place the memory has not seen)."""
    import numpy as np

    frames = [SAMPLE / "rgb" / line.split()[1].split("/")[1]
              for line in pathlib.Path(sample_list).read_text().splitlines() if line and line[0] != "#"]
    noise = work / "noise.pgm"
    rng = np.random.default_rng(7)
    pixels = rng.integers(0, 256, size=(240, 320), dtype=np.uint8)
    noise.write_bytes(b"P5 320 240 255\n" + pixels.tobytes())
    return [frames[5], frames[30], frames[55], noise]


def test_answers_placed_on_their_key_images(browser, vmap_cli, posed, sample_list, work):
    """--answers: the accepted queries of `vmap localize --json` on their key images, the
    others listed with their reason; a metric pose (the JSON's "pose", as the localizer
    answers it with a calibrated camera and posed key images) drawn where one is given."""
    memory, info = posed
    answers = json.loads(run_vmap(vmap_cli, "localize", "--memory", memory, *queries(sample_list, work), "--json").stdout)
    accepted = [q for q in answers["queries"] if q["localized"]]
    assert len(accepted) >= 2 and any(not q["localized"] for q in answers["queries"])
    # A metric pose on the first accepted answer, none (with its reason) on another.
    first = accepted[0]
    first["pose"] = {"position": [0.25, 0.1, -0.4], "quaternion": [0.0, 0.0, 0.0, 1.0], "inliers": 42,
                     "reprojection_error_px": 0.8}
    accepted[1]["pose"] = None
    accepted[1]["pose_reason"] = "no baseline between the key images that see it"
    file = work / "answers.json"
    file.write_text(json.dumps(answers))
    page = fresh(work / "page_answers")
    out = json.loads(run_vmap(vmap_cli, "view", memory, "--out", page, "--answers", file, "--json").stdout)
    assert (out["answers"], out["placed"]) == (len(answers["queries"]), len(accepted))
    open_page(browser, page)
    assert console_errors(browser) == []
    placed = hook(browser, "placed")
    assert [(p["image"], p["key"]) for p in placed] == [(q["image"], q["key"]) for q in accepted]
    assert hook(browser, "answerMarks") == len(accepted)
    text = browser.find_element("id", "answers").text
    assert "0.250, 0.100, -0.400" in text
    assert "no baseline between the key images that see it" in text
    for q in answers["queries"]:
        if not q["localized"]:
            assert q["reason"] in text
    assert "not placed" in browser.find_element("id", "unplaced").text
    # The pose drawn on the map: the data holds it in the map's plane (right +z, top +x).
    pose = browser.execute_script("return window.VMAP_VIEW.answers.find(a => a.pose).pose")
    assert (pose["u"], pose["v"]) == (-0.4, 0.25)


def test_answers_of_another_memory_are_refused(vmap_cli, posed, work):
    memory, info = posed
    file = work / "answers_other.json"
    file.write_text(json.dumps({"queries": [{"image": "x.png", "status": "accepted", "reason": "r", "confidence": 0.9,
                                             "localized": True, "key": 100000}]}))
    page = work / "page_refused"
    r = run_vmap(vmap_cli, "view", memory, "--out", page, "--answers", file, check=False)
    assert r.returncode == 1 and "key image 100000" in r.stderr
    assert not page.exists()
    file.write_text("{not json")
    r = run_vmap(vmap_cli, "view", memory, "--out", page, "--answers", file, check=False)
    assert r.returncode == 4 and "--answers" in r.stderr
    assert not page.exists()


def test_python_view_places_answers(browser, two_runs, work):
    """memory.view(folder, answers=...): the same page from Python, with localize()'s answers."""
    import vmap

    memory, info = two_runs
    m = vmap.VisualMemory.open(str(memory), read_only=True)
    frames = list(vmap.frames(str(SAMPLE / "rgb.txt"), grey=True))
    answers = [(name, m.localize(image)) for image, _, name in frames[10:13]]
    page = fresh(work / "page_python")
    out = m.view(str(page), answers=answers)
    assert out["key_images"] == len(info["key_images"]) and out["answers"] == 3
    open_page(browser, page)
    assert console_errors(browser) == []
    expected = [(name, a.key) for name, a in answers if a]
    assert [(p["image"], p["key"]) for p in hook(browser, "placed")] == expected
    assert hook(browser, "marks") == len(info["key_images"])


def test_visual_map_of_build_out(browser, vmap_cli, sample_list, work):
    """The folder of `vmap build --out` (map.vmap with its key images): the time line, no loops."""
    built = fresh(work / "built")
    run_vmap(vmap_cli, "build", sample_list, "--out", built)
    page = fresh(work / "page_map")
    out = json.loads(run_vmap(vmap_cli, "view", built, "--out", page, "--json").stdout)
    assert out["loops"] == 0 and out["images"] == out["key_images"] > 0
    open_page(browser, page)
    assert console_errors(browser) == []
    assert hook(browser, "marks") == out["key_images"] and hook(browser, "lines") == 0
    click_key(browser, 1)
    wait_image(browser)


def test_fleet_shows_each_robot(browser, vmap_cli, sample_list, fleet_server, work):
    """A fleet's memory: one run per robot, every robot's key images, the loops within and
    between robots."""
    uri = fleet_server("view_fleet")
    run_vmap(vmap_cli, "build", sample_list, "--memory", uri, "--robot", "r1", "--end", "40")
    run_vmap(vmap_cli, "build", sample_list, "--memory", uri, "--robot", "r2", "--start", "20")
    fleet = json.loads(run_vmap(vmap_cli, "memory", "info", uri, "--json").stdout)
    robots = [r["robot"] for r in fleet["robots"]]
    keys = sum(r["key_images"] for r in fleet["robots"])
    loops = sum(r["loops"] for r in fleet["robots"]) + len(fleet["fleet_loops"])
    page = fresh(work / "page_fleet")
    out = json.loads(run_vmap(vmap_cli, "view", uri, "--out", page, "--json").stdout)
    assert (out["runs"], out["key_images"], out["loops"]) == (2, keys, loops)
    open_page(browser, page)
    assert console_errors(browser) == []
    assert browser.execute_script("return window.VMAP_VIEW.runs.map(r => r.name)") == robots
    legend = browser.find_element("id", "legend").text
    assert all(r in legend for r in robots)
    assert hook(browser, "marks") == keys and hook(browser, "lines") == loops
    # One robot alone: its sessions.
    page_r2 = fresh(work / "page_fleet_r2")
    out = json.loads(run_vmap(vmap_cli, "view", uri, "--robot", "r2", "--out", page_r2, "--json").stdout)
    assert out["key_images"] == fleet["robots"][1]["key_images"]


def test_missing_or_damaged_memory_writes_no_page(vmap_cli, two_runs, work):
    """The usual error and exit code, and no page: a missing memory, a damaged one, a file
    that is no memory; an --out folder of other files is refused and left as it was."""
    memory, info = two_runs
    page = work / "page_never"
    r = run_vmap(vmap_cli, "view", work / "missing.vmdb", "--out", page, check=False)
    assert r.returncode == 3 and "error" in r.stderr and not page.exists()
    damaged = work / "damaged.vmdb"
    data = bytearray(memory.read_bytes())
    for i in range(4096, len(data), 4096):  # every page's first bytes after the header
        data[i:i + 64] = b"\xa5" * 64
    damaged.write_bytes(bytes(data))
    r = run_vmap(vmap_cli, "view", damaged, "--out", page, check=False)
    assert r.returncode == 4 and "error" in r.stderr and not page.exists()
    other = work / "notes.txt"
    other.write_text("not a memory\n")
    r = run_vmap(vmap_cli, "view", other, "--out", page, check=False)
    assert r.returncode == 4 and not page.exists()
    mine = work / "my_folder"
    mine.mkdir(exist_ok=True)
    (mine / "keep.txt").write_text("mine\n")
    r = run_vmap(vmap_cli, "view", memory, "--out", mine, check=False)
    assert r.returncode == 2 and "my_folder" in r.stderr
    assert sorted(os.listdir(mine)) == ["keep.txt"] and (mine / "keep.txt").read_text() == "mine\n"
    # An earlier page is replaced whole.
    again = fresh(work / "page_again")
    run_vmap(vmap_cli, "view", memory, "--out", again)
    run_vmap(vmap_cli, "view", memory, "--out", again, "--image-side", "0")
    assert not (again / "img").exists()
