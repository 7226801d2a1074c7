"""vmap.detect_loops, vmap.LoopDetector and vmap.evaluate (examples/python/part_loops.cpp).

On the RTAB-Map loop samples the module's loops and figures must be those of
`vmap loops --json` edge for edge; evaluate() is checked on hand-made ground truth
whose answer is known by counting.
"""

import json
import subprocess

import numpy
import pytest

import vmap

LABELS = "examples/data/rtabmap_loop_yolox.txt"


def cli_loops(vmap_cli, *args):
    out = subprocess.run([vmap_cli, "loops", *map(str, args), "--json"], check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


def edges(loops):
    """Loops as comparable tuples (the JSON's and vmap.Loop's fields)."""
    out = []
    for l in loops:
        if isinstance(l, dict):
            out.append((l["query"], l["match"], l["query_name"], l["match_name"], l["confidence"], l["inliers"],
                        l["matches"], l["inlier_ratio"], l["significance"], l["spread"], l["bow_score"]))
        else:
            out.append((l.query, l.match, l.query_name, l.match_name, l.confidence, l.inliers, l.matches,
                        l.inlier_ratio, l.significance, l.spread, l.bow_score))
    return out


@pytest.fixture(scope="module")
def rtabmap(shared):
    folder = shared / "data" / "rtabmap_loop"
    return folder / "images", folder / "gt_loop_matrix_84x84.txt"


@pytest.fixture(scope="module")
def bow_run(rtabmap):
    images, _ = rtabmap
    return vmap.detect_loops(str(images))


# ---------------------------------------------------------------------------------------
# The command line's run, from Python


def test_bow_loops_and_figures_equal_the_command_line(rtabmap, bow_run, vmap_cli):
    images, gt = rtabmap
    cli = cli_loops(vmap_cli, images, "--gt", gt)
    assert bow_run.rank == cli["rank"] == "bow"
    assert bow_run.frames == cli["frames"] == 84
    assert bow_run.verifications == cli["verifications"]
    assert bow_run.stationary == cli["stationary"]
    assert len(bow_run.loops) > 30
    assert edges(bow_run.loops) == edges(cli["loops"])
    e = vmap.evaluate(bow_run, str(gt))
    assert e.positives == cli["loops_gt"] == 44
    assert (e.true_positives, e.false_positives) == (cli["true_positives"], cli["false_positives"])
    assert e.precision == cli["precision"]
    assert e.recall == cli["recall"]
    assert e.recall_at_100_precision == cli["recall_at_100_precision"]
    assert e.threshold_at_100_precision == cli["threshold_at_100_precision"]
    assert e.threshold == cli["min_confidence"] == 0.5
    assert bow_run.min_confidence == cli["min_confidence"] and bow_run.window == cli["options"]["window"] == 10
    assert bow_run.skipped_frames == cli["skipped_frames"] == 0
    assert [(l.query_time, l.match_time) for l in bow_run.loops] == [(l["query_time"], l["match_time"]) for l in cli["loops"]]
    assert len(bow_run.times) == 84 and all(bow_run.times[l.query] == l.query_time for l in bow_run.loops)


def test_labelled_tree_ranked_run_equals_the_command_line(repo, rtabmap, vmap_cli):
    images, gt = rtabmap
    labels = repo / LABELS
    cli = cli_loops(vmap_cli, images, "--labels", labels, "--gt", gt)
    run = vmap.detect_loops(images, labels=str(labels))
    assert run.rank == cli["rank"] == "tree_ranked"
    assert run.labels_kept == cli["labels_kept"]
    assert edges(run.loops) == edges(cli["loops"])
    e = vmap.evaluate(run, numpy.loadtxt(gt, dtype=numpy.uint8))
    assert (e.precision, e.recall, e.recall_at_100_precision) == (
        cli["precision"], cli["recall"], cli["recall_at_100_precision"])
    # The same detections given per frame as Python tuples give the same run.
    per_frame = [[] for _ in range(84)]
    for line in labels.read_text().splitlines():
        if line.startswith("#") or not line.strip():
            continue
        f, label, score, x, y, w, h = line.split()
        per_frame[int(f)].append((int(label), float(score), float(x), float(y), float(w), float(h)))
    again = vmap.detect_loops(images, labels=per_frame)
    assert edges(again.loops) == edges(run.loops)


def test_options_reach_the_detector_as_on_the_command_line(rtabmap, vmap_cli):
    images, gt = rtabmap
    cli = cli_loops(vmap_cli, images, "--rank", "bow", "--top-k", 4, "--min-confidence", 0.3, "--window", 15,
                    "--nfeatures", 500, "--gt", gt)
    run = vmap.detect_loops(images, rank="bow", top_k=4, min_confidence=0.3, window=15, nfeatures=500)
    assert edges(run.loops) == edges(cli["loops"])
    assert run.verifications == cli["verifications"]
    e = vmap.evaluate(run, str(gt))
    assert e.threshold == 0.3
    assert (e.precision, e.recall, e.recall_at_100_precision) == (
        cli["precision"], cli["recall"], cli["recall_at_100_precision"])


def test_the_chance_rate_is_the_stacks_unless_given(rtabmap, bow_run):
    images, _ = rtabmap
    assert vmap.measured_chance_rate() == 0.1
    assert bow_run.chance_inlier_rate == vmap.measured_chance_rate("orb")
    # SIFT's and XFeat*'s matches fit a model by chance far less often than ORB's.
    assert vmap.measured_chance_rate("sift") < 0.05
    assert vmap.measured_chance_rate("xfeat-star") < 0.05
    assert vmap.LoopDetector(features="sift").chance_inlier_rate == vmap.measured_chance_rate("sift")
    assert vmap.LoopDetector(chance_inlier_rate=0.05).chance_inlier_rate == 0.05
    run = vmap.detect_loops(images, rank="bow", chance_inlier_rate=0.05)
    assert run.chance_inlier_rate == 0.05
    # A lower rate makes the same inliers more significant: no loop of both runs loses
    # confidence.
    before = {(l.query, l.match): l.confidence for l in bow_run.loops}
    after = {(l.query, l.match): l.confidence for l in run.loops}
    both = set(before) & set(after)
    assert len(both) > 30
    assert all(after[k] >= before[k] for k in both)
    assert any(after[k] > before[k] for k in both if before[k] < 1.0)
    with pytest.raises(vmap.Error, match="features"):
        vmap.measured_chance_rate("surf")


def test_calibrate_chance_rate_equals_the_command_line(rtabmap, shared, vmap_cli):
    images, _ = rtabmap
    cabinet = shared / "data" / "tum_fr3_cabinet_kf" / "rgb.txt"
    c = vmap.calibrate_chance_rate([images, cabinet])
    out = subprocess.run([vmap_cli, "calibrate", str(images), str(cabinet), "--json"], check=True, capture_output=True,
                         text=True)
    cli = json.loads(out.stdout)
    assert (c.rate, c.pairs, c.weighed, c.strongest_significance) == (
        cli["rate"], cli["pairs"], cli["weighed"], cli["strongest_significance"])
    assert 0.05 < c.rate < 0.2
    assert vmap.calibrate_chance_rate([images, cabinet], seed=2).rate != c.rate
    with pytest.raises(vmap.Error, match="needs at least two places"):
        vmap.calibrate_chance_rate([images])
    with pytest.raises(vmap.Error, match="pairs: at least 100"):
        vmap.calibrate_chance_rate([images, cabinet], pairs=10)


def test_poses_ground_truth_equals_the_command_line(shared, vmap_cli):
    folder = shared / "data" / "tum_fr3_cabinet_kf"
    frames, poses = folder / "rgb.txt", folder / "truth_cam_poses.txt"
    opts = ["--rank", "brute_force", "--min-confidence", 0.2]
    cli = cli_loops(vmap_cli, frames, "--gt-poses", poses, "--gt-distance", 1.0, "--gt-angle", 45, *opts)
    run = vmap.detect_loops(str(frames), rank="brute_force", min_confidence=0.2)
    assert edges(run.loops) == edges(cli["loops"])
    by_file = vmap.evaluate(run, poses=str(poses), max_distance=1.0, max_angle=45.0)
    assert by_file.positives == cli["loops_gt"] > 0
    assert (by_file.true_positives, by_file.false_positives) == (cli["true_positives"], cli["false_positives"])
    assert (by_file.precision, by_file.recall, by_file.recall_at_100_precision) == (
        cli["precision"], cli["recall"], cli["recall_at_100_precision"])
    # The file holds one pose per frame (timestamp tx ty tz qx qy qz qw): as an N x 7 array
    # it gives the same ground truth.
    table = numpy.loadtxt(poses)[:, 1:8]
    by_array = vmap.evaluate(run, poses=table, max_distance=1.0, max_angle=45.0)
    assert numpy.array_equal(by_array.ground_truth, by_file.ground_truth)
    assert (by_array.precision, by_array.recall) == (by_file.precision, by_file.recall)


def test_images_features_and_paths_give_the_same_loops(rtabmap, bow_run):
    images, _ = rtabmap
    frames = [image for image, _, _ in vmap.frames(str(images), grey=True)]
    from_arrays = vmap.detect_loops(frames)
    assert [(l.query, l.match, l.confidence) for l in from_arrays.loops] == [
        (l.query, l.match, l.confidence) for l in bow_run.loops]
    assert from_arrays.names[:2] == ["0", "1"]
    features = [vmap.Descriptor("orb").extract(f) for f in frames]
    from_features = vmap.detect_loops(features)
    assert edges(from_features.loops)[0][:2] == edges(bow_run.loops)[0][:2]
    assert [(l.query, l.match, l.inliers) for l in from_features.loops] == [
        (l.query, l.match, l.inliers) for l in bow_run.loops]


def test_incremental_detector_decides_as_the_batch_run(rtabmap, bow_run):
    images, _ = rtabmap
    frames = [image for image, _, _ in vmap.frames(str(images), grey=True)]
    features = [vmap.Descriptor("orb").extract(f) for f in frames]
    # A vocabulary learned on the same features with the same seed: the batch run's.
    detector = vmap.LoopDetector(vocabulary=features)
    assert detector.rank == "bow"
    assert detector.window == bow_run.window == 10 and detector.min_confidence == bow_run.min_confidence == 0.5
    decisions = [detector.add(f) for f in features]
    assert len(detector) == 84
    assert detector.verifications == bow_run.verifications
    batch = bow_run.decisions
    assert [(d.frame, d.status, d.best, d.confidence, d.inliers) for d in decisions] == [
        (d.frame, d.status, d.best, d.confidence, d.inliers) for d in batch]
    assert [(d.frame, d.best) for d in decisions if d.loop] == [(l.query, l.match) for l in bow_run.loops]
    # Images go through the detector's own descriptor: the same decisions again.
    from_images = vmap.LoopDetector(vocabulary=features)
    assert [from_images.add(f).best for f in frames[:45]] == [d.best for d in decisions[:45]]


def test_decisions_describe_every_frame(bow_run):
    d = bow_run.decisions
    assert [x.frame for x in d] == list(range(84))
    # Frames within the window of the start have no candidate at all.
    assert d[0].status == "too little evidence" and d[0].best is None and d[0].reason == "no candidates"
    accepted = [x for x in d if x.loop]
    assert len(accepted) == len(bow_run.loops)
    assert all(x.status == "accepted" and x.confidence >= 0.5 for x in accepted)
    # The runner-up of a decision is another candidate, no more confident than the best.
    for x in d:
        if x.second is not None:
            assert x.second != x.best and x.second_confidence <= x.confidence
        assert x.failed_verifications <= x.verifications and x.consistent_queries >= 0
        assert x.labels == [] and min(x.rank_ms, x.verify_ms, x.decide_ms) >= 0.0
    assert sum(x.verifications for x in d) == bow_run.verifications
    chosen = [c for c in accepted[0].considered if c[4] == "chosen"]
    assert chosen and chosen[0][0] == accepted[0].best
    scores = bow_run.scores
    assert scores.shape == (84, 3) and scores.dtype == numpy.float64
    assert scores[0, 1] == -1
    # The run's scores evaluate as the run does.
    gt = numpy.zeros((84, 84), bool)
    for l in bow_run.loops:
        gt[l.query, l.match] = True
    assert vmap.evaluate(scores, gt).recall == vmap.evaluate(bow_run, gt).recall == 1.0


def test_progress_and_determinism(rtabmap, bow_run):
    images, _ = rtabmap
    calls = []
    run = vmap.detect_loops(images, progress=lambda stage, done, total: calls.append((stage, done, total)))
    assert edges(run.loops) == edges(bow_run.loops)
    assert [(d.status, d.best, d.confidence) for d in run.decisions] == [
        (d.status, d.best, d.confidence) for d in bow_run.decisions]
    stages = [c[0] for c in calls]
    assert stages.count("features") == 84 and stages.count("loops") == 84 and "vocabulary" in stages
    assert calls[-1] == ("loops", 84, 84)


# ---------------------------------------------------------------------------------------
# evaluate() on hand-made ground truth


def test_evaluate_counts_a_known_answer():
    # 6 frames; queries 3, 4 and 5 have a true loop (positives = 3).
    gt = numpy.zeros((6, 6), dtype=numpy.uint8)
    gt[3, 0] = gt[4, 1] = gt[5, 2] = 1
    loops = [
        (0, None, 0.0),
        (1, None, 0.0),
        (2, 0, 0.2),  # false, weak
        (3, 0, 0.9),  # true
        (4, 2, 0.7),  # false (4 closes with 1)
        (5, 2, 0.6),  # true
    ]
    e = vmap.evaluate(loops, gt, min_confidence=0.5)
    assert (e.true_positives, e.false_positives, e.false_negatives, e.positives) == (2, 1, 1, 3)
    assert e.precision == 2 / 3 and e.recall == 2 / 3
    # Only threshold 0.9 is free of false positives: recall 1/3 there.
    assert e.recall_at_100_precision == 1 / 3
    assert e.threshold_at_100_precision == 0.9
    assert e.curve.shape == (4, 5)
    numpy.testing.assert_array_equal(e.curve[:, 0], [0.9, 0.7, 0.6, 0.2])
    numpy.testing.assert_array_equal(e.curve[:, 1], [1.0, 0.5, 2 / 3, 0.5])
    numpy.testing.assert_array_equal(e.curve[:, 2], [1 / 3, 1 / 3, 2 / 3, 2 / 3])
    numpy.testing.assert_array_equal(e.curve[:, 3:], [[1, 0], [1, 1], [2, 1], [2, 2]])
    # The same as an array (match -1: none) and with a bool matrix.
    rows = numpy.array([(q, -1 if m is None else m, s) for q, m, s in loops])
    assert repr(vmap.evaluate(rows, gt.astype(bool))) == repr(e)
    # The default threshold is the decision's (0.5); at 0.65 only two detections remain.
    assert vmap.evaluate(loops, gt).precision == 2 / 3
    high = vmap.evaluate(loops, gt, min_confidence=0.65)
    assert (high.true_positives, high.false_positives, high.precision, high.recall) == (1, 1, 0.5, 1 / 3)


def test_evaluate_from_positions():
    # A square loop: frame 12 comes back within 0.3 m of frame 0, the others are far.
    positions = numpy.array([[float(k), 0.0, 0.0] for k in range(12)] + [[0.3, 0.0, 0.0]])
    e = vmap.evaluate([(12, 0, 0.8), (11, 0, 0.9)], poses=positions, max_distance=0.5, window=10)
    assert e.positives == 1 and e.frames == 13
    assert e.ground_truth[12, 0] and e.ground_truth.sum() == 1
    assert (e.true_positives, e.false_positives) == (1, 1)
    assert e.recall_at_100_precision == 0.0 and e.threshold_at_100_precision is None


def test_no_detection_means_precision_one_recall_zero():
    gt = numpy.eye(3, k=-1, dtype=bool)
    e = vmap.evaluate([(1, None, 0.0), (2, None, 0.0)], gt)
    assert (e.precision, e.recall, e.positives, e.curve.shape) == (1.0, 0.0, 2, (0, 5))


# ---------------------------------------------------------------------------------------
# Errors


def test_bad_ground_truth_raises_vmap_error(bow_run):
    with pytest.raises(vmap.Error, match=r"ground_truth: an array of shape \(3, 4\)"):
        vmap.evaluate([(0, None, 0.0)], numpy.zeros((3, 4), numpy.uint8))
    with pytest.raises(vmap.Error, match="ground_truth: a float64 array"):
        vmap.evaluate([(0, None, 0.0)], numpy.zeros((3, 3)))
    with pytest.raises(vmap.Error, match=r"ground_truth: cell \(1, 0\) is 2"):
        vmap.evaluate([(0, None, 0.0)], numpy.array([[0, 0], [2, 0]], numpy.uint8))
    with pytest.raises(vmap.Error, match="ground_truth: covers 3 frames but the run has 84"):
        vmap.evaluate(bow_run, numpy.zeros((3, 3), bool))
    with pytest.raises(vmap.Error, match="outside the ground truth"):
        vmap.evaluate([(5, 0, 1.0)], numpy.zeros((3, 3), bool))
    with pytest.raises(vmap.Error, match="give one of ground_truth"):
        vmap.evaluate([(0, None, 0.0)])
    with pytest.raises(vmap.Error, match=r"poses: an array of shape \(4, 2\)"):
        vmap.evaluate([(0, None, 0.0)], poses=numpy.zeros((4, 2)))
    with pytest.raises(vmap.Error, match="no_such_gt.txt"):
        vmap.evaluate([(0, None, 0.0)], "no_such_gt.txt")


def test_bad_input_raises_vmap_error(tmp_path, sample_frames):
    with pytest.raises(vmap.Error, match="no_such_folder"):
        vmap.detect_loops(str(tmp_path / "no_such_folder"))
    frames = [image for image, _, _ in sample_frames[:3]]
    with pytest.raises(vmap.Error, match="rank: unknown 'fast'"):
        vmap.detect_loops(frames, rank="fast")
    with pytest.raises(vmap.Error, match="rank=tree needs labels"):
        vmap.detect_loops(frames, rank="tree")
    with pytest.raises(vmap.Error, match=r"min_confidence must be in \[0, 1\]"):
        vmap.detect_loops(frames, min_confidence=1.5)
    with pytest.raises(vmap.Error, match=r"source\[1\]: a float64 array"):
        vmap.detect_loops([frames[0], frames[1].astype(float)])
    with pytest.raises(vmap.Error, match="source: an empty list"):
        vmap.detect_loops([])
    with pytest.raises(vmap.Error, match="features: unknown descriptor 'surf'"):
        vmap.detect_loops(frames, features="surf")
    with pytest.raises(vmap.Error, match="rank=bow ranks by bag of words"):
        vmap.LoopDetector(rank="bow")
    with pytest.raises(vmap.Error, match="a detection is"):
        vmap.LoopDetector().add(frames[0], detections=[(1, 0.9)])


def test_rank_all_is_the_old_name_of_brute_force():
    with pytest.warns(DeprecationWarning, match="rank='all' is now rank='brute_force'"):
        detector = vmap.LoopDetector(rank="all")
    assert detector.rank == "brute_force"


def test_detector_without_vocabulary_verifies_every_older_frame(sample_frames):
    detector = vmap.LoopDetector(window=2)
    assert detector.rank == "brute_force"
    for image, _, _ in sample_frames[:6]:
        d = detector.add(image)
    # Frame 5 with window 2: frames 0, 1 and 2 are its candidates, each verified.
    assert (d.frame, d.candidates, d.verifications) == (5, 3, 3)
