"""vmap.KeyframeSelector, vmap.VisualMap, vmap.save_map / load_map and vmap.sweep
(examples/python/part_keyframes.cpp), checked against the `vmap build` and `vmap sweep`
command lines on the 60 sample frames."""

import json
import os
import subprocess

import numpy
import pytest

import vmap


def run_json(cli, *args):
    done = subprocess.run([cli, *args, "--json"], check=True, capture_output=True, text=True)
    return json.loads(done.stdout)


def push_all(selector, frames):
    return [selector.push(image, timestamp, name) for image, timestamp, name in frames]


def result_tuple(r):
    return (r.frame_index, r.similarity, r.exact, r.raw_matches, r.verified_matches, r.status, r.key_taken,
            r.key_frame, r.reason)


@pytest.fixture(scope="module")
def selected(sample_frames):
    """The default selector (ORB 1000, MAGSAC, tau 0.3) after the 60 sample frames, and its results."""
    selector = vmap.KeyframeSelector()
    results = push_all(selector, sample_frames)
    return selector, results


def test_key_images_equal_the_command_line(selected, sample_list, vmap_cli):
    selector, results = selected
    cli = run_json(vmap_cli, "build", sample_list)
    m = selector.map
    assert m.frames == cli["frames"] == 60
    assert m.key_frames == cli["key_frames"]
    assert len(m) == cli["key_images"]
    stats = m.stats()
    assert stats["min_matches"] == cli["min_matches"]
    assert stats["max_matches"] == cli["max_matches"]
    assert stats["mean_matches"] == pytest.approx(cli["mean_matches"], rel=1e-12)
    assert m.quality() == pytest.approx(cli["quality"], rel=1e-12)
    # Frame for frame: a key image is taken exactly where the map gained one.
    taken = [r.key_frame for r in results if r.key_taken]
    assert taken == cli["key_frames"]
    assert [r.frame_index for r in results] == list(range(60))
    assert results[0].reason == "first frame" and results[0].similarity == 1.0
    for r in results:
        assert r.key_taken == (r.reason != "similar to the key image")
        if not r.key_taken:
            assert r.exact and r.similarity >= 0.3 and r.status == "verified"
        if r.reason == "similarity below tau":
            assert r.exact and r.similarity < 0.3
        if r.reason.startswith("match bound below tau"):
            assert not r.exact and r.similarity < 0.3 and r.verified_matches == 0


def test_map_equals_the_command_lines_map_file(selected, sample_list, vmap_cli, tmp_path):
    selector, _ = selected
    out = tmp_path / "out"
    subprocess.run([vmap_cli, "build", sample_list, "--out", str(out)], check=True, capture_output=True)
    theirs = vmap.load_map(out / "map.vmap")
    ours = selector.map
    assert theirs.frames == ours.frames
    assert theirs.key_frames == ours.key_frames
    assert [k.name for k in theirs.keys] == [k.name for k in ours.keys]
    assert [k.timestamp for k in theirs.keys] == [k.timestamp for k in ours.keys]
    assert theirs.similarities == ours.similarities
    for a, b in zip(theirs.pairs, ours.pairs):
        assert (a.status, a.matches, a.inliers) == (b.status, b.matches, b.inliers)
        numpy.testing.assert_array_equal(a.fundamental, b.fundamental)
    for a, b in zip(theirs.keys, ours.keys):
        numpy.testing.assert_array_equal(a.features.descriptors, b.features.descriptors)
    # The command line keeps the colour pixels for its pictures; the selector here keeps none.
    assert all(k.image is not None for k in theirs.keys)
    assert all(k.image is None for k in ours.keys)


def test_fundamental_matrices_are_epipolar(selected):
    m = selected[0].map
    assert len(m.fundamentals) == len(m.pairs) == len(m.keys) - 1
    for k, (pair, f) in enumerate(zip(m.pairs, m.fundamentals)):
        assert pair.status == "verified"
        assert f.shape == (3, 3) and f.dtype == numpy.float64
        numpy.testing.assert_array_equal(f, pair.fundamental)
        singular = numpy.linalg.svd(f, compute_uv=False)
        assert singular[1] > 1e-6 * singular[0]
        assert singular[2] < 1e-9 * singular[0], "F must have rank 2"
        # x_{k+1}^T F x_k = 0: the verified matches lie on their epipolar lines.
        a, b = m.keys[k].features, m.keys[k + 1].features
        matches = vmap.match(a, b).astype(int)
        assert len(matches) == pair.matches
        xa = numpy.c_[a.keypoints[matches[:, 0], :2], numpy.ones(len(matches))]
        xb = numpy.c_[b.keypoints[matches[:, 1], :2], numpy.ones(len(matches))]
        lines = xa @ f.T  # epipolar lines in image k+1
        distance = numpy.abs(numpy.sum(xb * lines, axis=1)) / numpy.hypot(lines[:, 0], lines[:, 1])
        close = int(numpy.count_nonzero(distance < 2.0))
        assert close >= 0.9 * pair.inliers
        assert 0.0 < pair.similarity <= 1.0
        assert pair.inliers <= pair.matches


def test_quality_is_eq_7(selected):
    m = selected[0].map
    n, keys, s = m.frames, len(m.keys), m.similarities
    assert m.quality() == pytest.approx(0.5 * ((1 - keys / n) + sum(s) / len(s)), rel=1e-12)
    assert m.quality("paper_literal") == pytest.approx(0.5 * ((1 - keys / n) + sum(s) / keys), rel=1e-12)
    assert m.stats()["quality"] == m.quality()
    assert m.stats()["mean_similarity"] == pytest.approx(numpy.mean(s), rel=1e-12)
    assert m.stats()["mean_matches"] == pytest.approx(numpy.mean([p.inliers for p in m.pairs]), rel=1e-12)
    with pytest.raises(vmap.Error, match="form"):
        m.quality("harmonic")


def test_pushing_twice_is_deterministic(selected, sample_frames):
    first_selector, first = selected
    again = vmap.KeyframeSelector()
    second = push_all(again, sample_frames)
    assert [result_tuple(r) for r in second] == [result_tuple(r) for r in first]
    assert again.map == first_selector.map
    # reset() starts a new sequence that gives the same map again.
    again.reset()
    assert len(again.map) == 0 and again.map.frames == 0
    assert [result_tuple(r) for r in push_all(again, sample_frames)] == [result_tuple(r) for r in first]
    assert again.map == first_selector.map


@pytest.mark.parametrize("single_thread", [False, True])
def test_push_frames_equals_pushing_frame_by_frame(selected, sample_list, single_thread):
    by_frame, results = selected
    whole = vmap.KeyframeSelector()
    done = []
    sizes = []

    def progress(frames):
        done.append(frames)
        sizes.append(whole.map.frames)  # the map may be read between two frames

    pushed = whole.push_frames(sample_list, single_thread=single_thread, progress=progress, progress_every=20)
    assert done == [20, 40, 60]
    assert sizes == [20, 40, 60]
    assert [result_tuple(r) for r in pushed] == [result_tuple(r) for r in results]
    assert whole.map == by_frame.map  # frame indices, names, timestamps, features, links


def test_push_frames_in_chunks_continues_the_sequence(selected, sample_list):
    chunked = vmap.KeyframeSelector()
    chunked.push_frames(sample_list, end=25)
    with pytest.raises(vmap.Error, match="start=25"):
        chunked.push_frames(sample_list, start=10)
    chunked.push_frames(sample_list, start=25)
    assert chunked.map == selected[0].map


def test_progress_errors_stop_the_run(sample_list):
    selector = vmap.KeyframeSelector()

    def stop(frames):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        selector.push_frames(sample_list, progress=stop, progress_every=10)
    # The frames pushed before the callback raised stay in the map.
    assert selector.map.frames >= 10


def test_sweep_equals_the_command_line(sample_list, vmap_cli, selected):
    taus = [0.1, 0.3, 0.5, 0.9]
    rows = vmap.sweep(sample_list, taus)
    cli = run_json(vmap_cli, "sweep", sample_list, "--taus", ",".join(map(str, taus)))
    assert len(rows) == len(cli["rows"]) == len(taus)
    for row, theirs in zip(rows, cli["rows"]):
        assert set(theirs) <= set(row)
        for column, value in theirs.items():
            assert row[column] == pytest.approx(value, rel=1e-12), column
    best = [row["threshold"] for row in rows if row["best"]]
    assert best == [cli["best_threshold"]]
    # The sweep's row at tau 0.3 is the selector's map at tau 0.3 (sweep.hpp's promise).
    m = selected[0].map
    assert rows[1]["key_frames"] == m.key_frames
    assert rows[1]["quality"] == pytest.approx(m.quality(), rel=1e-12)
    # The default thresholds are the paper's 0.1..0.9, and single_thread changes nothing.
    defaults = vmap.sweep(sample_list, single_thread=True, end=30)
    assert [r["threshold"] for r in defaults] == pytest.approx([0.1 * k for k in range(1, 10)])
    assert all(r["frames"] == 30 for r in defaults)


def test_sweep_range_and_rule_equal_the_command_line(sample_list, vmap_cli):
    rows = vmap.sweep(sample_list, [0.4], start=5, end=50, stride=2, rule="current")
    cli = run_json(vmap_cli, "sweep", sample_list, "--taus", "0.4", "--start", "5", "--end", "50", "--stride", "2",
                   "--rule", "current")
    assert rows[0]["key_frames"] == cli["rows"][0]["key_frames"]
    assert rows[0]["quality"] == pytest.approx(cli["rows"][0]["quality"], rel=1e-12)
    assert rows[0]["frames"] == cli["frames"] == 23


def test_save_and_load_map_round_trip(selected, tmp_path):
    m = selected[0].map
    path = tmp_path / "map.vmap"
    selected[0].save_map(path)
    assert os.listdir(tmp_path) == ["map.vmap"]  # written atomically: no temporary file left
    loaded = vmap.load_map(path)
    assert loaded == m
    assert loaded.key_frames == m.key_frames and loaded.similarities == m.similarities
    vmap.save_map(loaded, str(tmp_path / "again.vmap"))
    assert (tmp_path / "again.vmap").read_bytes() == path.read_bytes()


def test_kept_key_images_are_copies_and_round_trip(sample_frames, tmp_path):
    selector = vmap.KeyframeSelector(keep_images=True, tau=0.2)
    frames = [(image.copy(), t, n) for image, t, n in sample_frames[:20]]
    push_all(selector, frames)
    m = selector.map
    by_index = {n: image for image, _, n in sample_frames}
    for k in m.keys:
        numpy.testing.assert_array_equal(k.image, by_index[k.name])
    for image, _, _ in frames:
        image[:] = 0  # the map does not alias the pushed arrays
    assert all(k.image.any() for k in selector.map.keys)
    selector.save_map(tmp_path / "images.vmap")
    loaded = vmap.load_map(tmp_path / "images.vmap")
    assert loaded == selector.map
    numpy.testing.assert_array_equal(loaded.keys[-1].image, selector.map.keys[-1].image)


def test_push_defaults_name_index_and_timestamp(sample_frames):
    selector = vmap.KeyframeSelector()
    r0 = selector.push(sample_frames[0][0])
    r1 = selector.push(sample_frames[1][0], timestamp=12.5)
    assert (r0.frame_index, r1.frame_index) == (0, 1)
    keys = selector.map.keys
    assert keys[0].name == "frame#0" and keys[0].timestamp == 0.0
    if len(keys) > 1:
        assert keys[1].timestamp == 12.5


def test_options_are_those_of_the_command_line(sample_list, vmap_cli, sample_frames):
    selector = vmap.KeyframeSelector("akaze", estimator="ransac", tau=0.5, rule="current")
    assert (selector.features, selector.estimator, selector.tau, selector.rule) == ("akaze", "ransac", 0.5, "current")
    selector.push_frames(sample_list, end=20)
    cli = run_json(vmap_cli, "build", sample_list, "--features", "akaze", "--estimator", "ransac", "--tau", "0.5",
                   "--rule", "current", "--end", "20")
    assert selector.map.key_frames == cli["key_frames"]
    assert selector.map.quality() == pytest.approx(cli["quality"], rel=1e-12)


def test_bad_input_raises_vmap_error(sample_frames, sample_list, tmp_path):
    with pytest.raises(vmap.Error, match="unknown method 'magic'"):
        vmap.KeyframeSelector(estimator="magic")
    with pytest.raises(vmap.Error, match="unknown descriptor 'surf'"):
        vmap.KeyframeSelector("surf")
    with pytest.raises(vmap.Error, match="needs model"):
        vmap.KeyframeSelector("xfeat")
    with pytest.raises(vmap.Error, match="unknown rule"):
        vmap.KeyframeSelector(rule="next")
    with pytest.raises(vmap.Error, match="tau"):
        vmap.KeyframeSelector(tau=1.5)
    with pytest.raises(vmap.Error, match="nfeatures"):
        vmap.KeyframeSelector(nfeatures=0)
    with pytest.raises(vmap.Error, match="camera"):
        vmap.KeyframeSelector(camera=str(tmp_path / "missing.yaml"))
    selector = vmap.KeyframeSelector()
    with pytest.raises(vmap.Error, match="image: a float"):
        selector.push(sample_frames[0][0].astype(numpy.float32))
    with pytest.raises(vmap.Error, match="shape"):
        selector.push(numpy.zeros((4, 4, 2), numpy.uint8))
    assert selector.map.frames == 0  # a refused image is not a frame
    with pytest.raises(vmap.Error, match="missing"):
        selector.push_frames(str(tmp_path / "missing.txt"))
    with pytest.raises(vmap.Error, match="end"):
        selector.push_frames(sample_list, start=10, end=10)
    with pytest.raises(vmap.Error, match="no frame"):
        selector.push_frames(sample_list, start=1000)
    with pytest.raises(vmap.Error):
        vmap.load_map(tmp_path / "missing.vmap")
    (tmp_path / "bad.vmap").write_bytes(b"VMAPKEYS" + bytes(40))
    with pytest.raises(vmap.Error, match="bad.vmap"):
        vmap.load_map(tmp_path / "bad.vmap")
    with pytest.raises(vmap.Error, match="missing"):
        vmap.sweep(str(tmp_path / "missing.txt"))
    with pytest.raises(vmap.Error, match="taus"):
        vmap.sweep(sample_list, [])
    with pytest.raises(vmap.Error, match="every threshold"):
        vmap.sweep(sample_list, [0.0, 0.5])
    with pytest.raises(vmap.Error, match="unknown method"):
        vmap.sweep(sample_list, [0.3], estimator="magic")


def test_camera_equals_the_command_line(repo, sample_list, vmap_cli):
    camera = str(repo / "examples" / "data" / "tum_fr1_camera.yaml")
    selector = vmap.KeyframeSelector(camera=camera)
    selector.push_frames(sample_list, end=30)
    cli = run_json(vmap_cli, "build", sample_list, "--camera", camera, "--end", "30")
    assert selector.map.key_frames == cli["key_frames"]
    assert selector.map.quality() == pytest.approx(cli["quality"], rel=1e-12)
    rows = vmap.sweep(sample_list, [0.3], camera=camera, end=30)
    assert rows[0]["key_frames"] == cli["key_frames"]


def test_learned_descriptor_equals_the_command_line(shared, sample_list, vmap_cli):
    model = str(shared / "models" / "xfeat_320x224.onnx")
    selector = vmap.KeyframeSelector("xfeat", model=model, nfeatures=500)
    selector.push_frames(sample_list, end=20)
    cli = run_json(vmap_cli, "build", sample_list, "--features", "xfeat", "--model", model, "--nfeatures", "500",
                   "--end", "20")
    assert selector.map.key_frames == cli["key_frames"]
    assert selector.map.quality() == pytest.approx(cli["quality"], rel=1e-12)
    assert selector.map.keys[0].features.norm == "l2"


def test_a_busy_selector_refuses_another_push(sample_list, sample_frames):
    selector = vmap.KeyframeSelector()

    def push_inside(frames):
        selector.push(sample_frames[0][0])

    with pytest.raises(vmap.Error, match="busy"):
        selector.push_frames(sample_list, progress=push_inside, progress_every=5)
    # The run stopped after 5 frames; the selector goes on after them.
    assert selector.map.frames == 5
    assert selector.push(sample_frames[5][0]).frame_index == 5
