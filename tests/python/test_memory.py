"""vmap.VisualMemory: in RAM, in a memory store, sessions, resume, read-only, and the
same answers as the command line's `vmap memory` on the same memory."""

import json
import subprocess
import threading
import time

import numpy as np
import pytest

import vmap


def cli_json(cli, *args):
    out = subprocess.run([cli, *args, "--json"], check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def key_frames(mem):
    return [k["frame_index"] for k in mem.keys]


def loop_pairs(loops):
    return [(e.key_from, e.key_to, e.link.inliers) for e in loops]


def test_push_frame_by_frame_equals_push_frames(sample_list, sample_frames):
    a = vmap.VisualMemory(vocabulary_after=5)
    steps = [a.push(img, timestamp=t, name=n) for img, t, n in sample_frames]
    b = vmap.VisualMemory(vocabulary_after=5)
    calls = []
    summary = b.push_frames(sample_list, progress=calls.append, progress_every=7)
    assert summary.pushed == 60 and summary.new_keys == b.key_images == a.key_images
    assert calls == list(range(7, 61, 7))
    assert key_frames(a) == key_frames(b)
    assert [k["timestamp"] for k in a.keys] == [k["timestamp"] for k in b.keys]
    assert [k["name"] for k in a.keys] == [k["name"] for k in b.keys]
    assert loop_pairs(a.loops) == loop_pairs(b.loops)
    # The steps tell which frames became key images: one new key per key image.
    assert sum(s.new_key is not None for s in steps) == a.key_images
    assert steps[0].new_key == 0 and steps[0].key_taken
    assert all(0.0 <= s.similarity <= 1.0 for s in steps)
    assert a.frames == 60 and a.last_frame_index == 59 and a.path is None
    assert a.vocabulary_words > 0


def test_push_frames_reads_as_vmap_frames_does(sample_list):
    # The same keywords as vmap.frames: half-size frames, from frame 10, a time offset.
    a = vmap.VisualMemory(vocabulary_after=5)
    for img, t, n in vmap.frames(sample_list, grey=True, start=10, resize=(320, 240), time_offset=2.5):
        assert img.shape == (240, 320)
        a.push(img, timestamp=t, name=n)
    b = vmap.VisualMemory(vocabulary_after=5)
    summary = b.push_frames(sample_list, start=10, resize=(320, 240), time_offset=2.5)
    assert summary.pushed == 50 and b.key_images == a.key_images
    # push_frames keeps the source's frame indices; push() numbers its own frames from 0.
    assert [f + 10 for f in key_frames(a)] == key_frames(b)
    assert [k["timestamp"] for k in a.keys] == [k["timestamp"] for k in b.keys]
    assert [k["name"] for k in a.keys] == [k["name"] for k in b.keys]
    _, first_time, first_name = next(iter(vmap.frames(sample_list, start=10)))
    assert b.keys[0]["name"] == first_name
    assert b.keys[0]["timestamp"] == pytest.approx(first_time + 2.5, abs=1e-9)


def test_store_round_trip_and_the_command_line_reads_it(tmp_path, sample_list, sample_frames, vmap_cli):
    path = tmp_path / "run.vmdb"
    with vmap.VisualMemory.create(str(path)) as mem:
        for img, t, _ in sample_frames:
            mem.push(img, timestamp=t)
        keys = mem.keys
        assert mem.stack["features"] == "orb"
    info = cli_json(vmap_cli, "memory", "info", str(path))
    assert info["frames"] == 60
    assert [k["frame_index"] for k in info["key_images"]] == [k["frame_index"] for k in keys]
    assert [k["name"] for k in info["key_images"]] == [k["name"] for k in keys]

    # The command line's memory of the same frames is the Python one, key for key.
    cli_store = tmp_path / "cli.vmdb"
    subprocess.run([vmap_cli, "memory", "build", sample_list, "--memory", str(cli_store)], check=True,
                   capture_output=True)
    from_cli = vmap.VisualMemory.open(str(cli_store), read_only=True)
    assert key_frames(from_cli) == [k["frame_index"] for k in keys]

    # Localization answers equal `vmap memory localize`'s.
    names = [sample_frames[i][2] for i in (3, 17, 31, 45)]
    rgb = sample_list.rsplit("/", 1)[0] + "/rgb/"
    images = [rgb + n for n in names]
    answers = cli_json(vmap_cli, "memory", "localize", str(path), *images)["queries"]
    reopened = vmap.VisualMemory.open(str(path), read_only=True)
    for i, answer in zip((3, 17, 31, 45), answers):
        got = reopened.localize(sample_frames[i][0])
        assert got.status == answer["status"] and got.reason == answer["reason"]
        assert got.key == answer["key"]
        assert got.confidence == pytest.approx(answer["confidence"], abs=1e-12)
        assert [m.key for m in got.matches] == [m["key"] for m in answer["matches"]]
        assert [m.inliers for m in got.matches] == [m["inliers"] for m in answer["matches"]]
        assert got.verified_candidates == answer["verified_candidates"]
        ev = answer["evidence"]
        assert (got.evidence.matches, got.evidence.inliers, got.evidence.model) == (ev["matches"], ev["inliers"], ev["model"])
        for field in ("inlier_ratio", "significance", "spread", "bow_score"):
            assert getattr(got.evidence, field) == pytest.approx(ev[field], abs=1e-12)
        f = np.array(answer["matches"][0]["model"]).reshape(3, 3)
        assert np.allclose(got.matches[0].model, f, atol=1e-12)
        assert got.matches[0].model_kind == answer["matches"][0]["model_kind"] == "fundamental"


def test_localize_answers_and_decisions(sample_frames):
    mem = vmap.VisualMemory(vocabulary_after=5)
    for img, t, _ in sample_frames[:40]:
        mem.push(img, timestamp=t)
    seen = mem.localize(sample_frames[20][0])
    assert seen.ok and bool(seen) and seen.status == "accepted" and seen.key is not None
    assert seen.matches[0].status == "verified" and seen.matches[0].inliers > 50
    # The accepted key image is one of the key images nearest in time to frame 20.
    assert abs(mem.keys[seen.key]["frame_index"] - 20) <= 5
    assert seen.relative_pose is None  # no camera
    # A raised threshold turns the same evidence into "unknown place".
    strict = mem.localize(sample_frames[20][0], min_confidence=1.0)
    assert strict.status in ("accepted", "unknown place")
    # Noise is no place: never accepted.
    noise = np.random.default_rng(1).integers(0, 256, (480, 640), dtype=np.uint8)
    answer = mem.localize(noise)
    assert not answer.ok and answer.status in ("unknown place", "too little evidence", "ambiguous") and answer.reason
    # An empty memory has too little evidence.
    empty = vmap.VisualMemory().localize(sample_frames[0][0])
    assert empty.status == "too little evidence" and empty.key is None


def test_localize_sequence_and_window(sample_frames, tmp_path, vmap_cli):
    # A memory of the even sample frames; the odd ones are the queries, in order.
    mem = vmap.VisualMemory(vocabulary_after=5)
    for img, t, _ in sample_frames[0::2]:
        mem.push(img, timestamp=t)
    queries = [img for img, _, _ in sample_frames[1::2]]
    alone = [mem.localize(img) for img in queries]
    answers = mem.localize_sequence(queries, window=8)
    assert len(answers) == len(queries) == 30
    for a, s in zip(alone, answers):
        assert a.sequence is None
        assert s.sequence is not None and s.sequence.window == 8
        assert s.sequence.on_line <= s.sequence.weighed <= 8
        assert s.sequence.single_confidence == pytest.approx(a.confidence, abs=1e-12)
        assert len(s.match_evidence) == len(s.matches)
        if a.ok:  # an image accepted alone keeps its key image
            assert s.key == a.key
    assert sum(s.ok for s in answers) >= sum(a.ok for a in alone)
    # The window of answers and the window of images decide the newest image alike.
    from_answers = mem.localize_window(alone[-5:])
    from_images = mem.localize_window(queries[-5:])
    assert from_answers.sequence.window == from_images.sequence.window == 5
    assert (from_answers.status, from_answers.key) == (from_images.status, from_images.key)
    assert from_answers.confidence == pytest.approx(from_images.confidence, abs=1e-12)
    with pytest.raises(vmap.Error, match="window must be in 1..100, got 0"):
        mem.localize_sequence(queries, window=0)
    with pytest.raises(vmap.Error, match="no answers given"):
        mem.localize_window([])
    with pytest.raises(vmap.Error, match="mixes Localization answers and images"):
        mem.localize_window([alone[0], queries[1]])
    # A window of 1 answers each image alone.
    assert all(a.sequence is None for a in mem.localize_sequence(queries[:3], window=1))


def test_resume_equals_the_uninterrupted_run(tmp_path, sample_frames):
    whole = vmap.VisualMemory.create(str(tmp_path / "whole.vmdb"), vocabulary_after=5)
    for img, t, _ in sample_frames:
        whole.push(img, timestamp=t)
    path = str(tmp_path / "parts.vmdb")
    first = vmap.VisualMemory.create(path, vocabulary_after=5)
    for img, t, _ in sample_frames[:30]:
        first.push(img, timestamp=t)
    first.close()
    with pytest.raises(vmap.Error, match="closed"):
        first.push(sample_frames[0][0])
    second = vmap.VisualMemory.open(path)
    assert second.frames == 30
    # sync() writes what the memory made since the last one: a reader then sees it.
    second.push(sample_frames[30][0], timestamp=sample_frames[30][1])
    second.sync()
    assert vmap.VisualMemory.open(path, read_only=True).frames == 31
    for img, t, _ in sample_frames[31:]:
        second.push(img, timestamp=t)
    assert key_frames(second) == key_frames(whole)
    assert loop_pairs(second.loops) == loop_pairs(whole.loops)


def test_sessions_find_loops_into_the_earlier_run(tmp_path, sample_frames):
    path = str(tmp_path / "two.vmdb")
    with vmap.VisualMemory.create(path, vocabulary_after=5) as mem:
        for img, t, _ in sample_frames:
            mem.push(img, timestamp=t)
        first_keys = mem.key_images
    with vmap.VisualMemory.open(path, new_session=True) as mem:
        assert mem.sessions == [{"first_key": 0, "first_frame": 0}, {"first_key": first_keys, "first_frame": 60}]
        for img, t, _ in sample_frames[:30]:
            mem.push(img, timestamp=t)
        across = [e for e in mem.loops if e.key_from >= first_keys]
        assert len(across) >= 5 and all(e.key_to < first_keys for e in across)
        # The second run revisits the same frames: each loop joins key images of nearby frames.
        for e in across:
            assert abs(mem.keys[e.key_from]["frame_index"] - 60 - mem.keys[e.key_to]["frame_index"]) <= 60
        assert (e.key_to, "loop") in mem.neighbours(e.key_from)
    reader = vmap.VisualMemory.open(path, read_only=True)
    assert reader.read_only and not mem.read_only
    assert len(reader.sessions) == 2 and loop_pairs(reader.loops) == loop_pairs(mem.loops)
    assert [k["session"] for k in reader.keys].count(1) == reader.key_images - first_keys
    with pytest.raises(vmap.Error, match="read-only"):
        reader.push(sample_frames[0][0])


def test_vmem_file_poses_images_and_export(tmp_path, sample_frames):
    mem = vmap.VisualMemory(images="png", vocabulary_after=5)
    for i, (img, t, _) in enumerate(sample_frames):
        pose = (0.1 * i, 0.0, 0.01 * i) if i % 2 == 0 else np.hstack([np.eye(3), [[i], [0], [0]]])
        mem.push(img, timestamp=t, pose=pose)
    k = mem.keys[1]
    i = k["frame_index"]
    if i % 2 == 0:
        assert k["pose"] == pytest.approx((0.1 * i, 0.0, 0.01 * i))
    else:
        assert np.allclose(k["pose"][:3, 3], [i, 0, 0])
    pixels = mem.key_image(1)
    assert np.array_equal(pixels, sample_frames[i][0])
    feats = mem.key_features(1)
    assert len(feats) > 100 and feats.descriptors.shape == (len(feats), 32)
    mem.save(str(tmp_path / "m.vmem"))
    again = vmap.VisualMemory.open(str(tmp_path / "m.vmem"))
    assert key_frames(again) == key_frames(mem) and np.array_equal(again.key_image(1), pixels)
    written = mem.export(str(tmp_path / "out"))
    assert "key_images.txt" in written and "loops.txt" in written
    rows = [l for l in (tmp_path / "out" / "key_images.txt").read_text().splitlines() if l and not l.startswith("#")]
    assert len(rows) == mem.key_images


def test_errors_name_the_input(tmp_path, sample_frames):
    other = tmp_path / "notes.txt"
    other.write_text("not a memory")
    with pytest.raises(vmap.Error, match="not a vmap memory"):
        vmap.VisualMemory.create(str(other))
    with pytest.raises(vmap.Error, match="not a vmap memory"):
        vmap.VisualMemory.open(str(other))
    with pytest.raises(vmap.Error, match="does not exist"):
        vmap.VisualMemory.open(str(tmp_path / "none.vmdb"))
    path = str(tmp_path / "m.vmdb")
    vmap.VisualMemory.create(path).close()
    with pytest.raises(vmap.Error, match="exists"):
        vmap.VisualMemory.create(path)
    vmap.VisualMemory.create(path, force=True).close()
    mem = vmap.VisualMemory()
    with pytest.raises(vmap.Error, match=r"pose: an array of shape \(2,\)"):
        mem.push(sample_frames[0][0], pose=(1.0, 2.0))
    with pytest.raises(vmap.Error, match="estimator: unknown method 'best'"):
        vmap.VisualMemory(estimator="best")
    with pytest.raises(vmap.Error, match="no key image 3"):
        mem.key_features(3)


def test_force_replaces_at_close_and_never_a_memory_being_written(tmp_path, sample_frames):
    path = str(tmp_path / "m.vmdb")
    with vmap.VisualMemory.create(path) as old:
        for img, t, _ in sample_frames[:10]:
            old.push(img, timestamp=t)
    writer = vmap.VisualMemory.open(path)
    with pytest.raises(vmap.Error, match="m.vmdb' is being written by another program"):
        vmap.VisualMemory.create(path, force=True)
    writer.close()
    assert vmap.VisualMemory.open(path, read_only=True).frames == 10
    new = vmap.VisualMemory.create(path, force=True)
    for img, t, _ in sample_frames[:20]:
        new.push(img, timestamp=t)
    # Readers see the old memory until the new one is closed; one never closed leaves it.
    assert vmap.VisualMemory.open(path, read_only=True).frames == 10
    new.close()
    assert vmap.VisualMemory.open(path, read_only=True).frames == 20
    unclosed = vmap.VisualMemory.create(path, force=True)
    unclosed.push(sample_frames[0][0])
    del unclosed
    assert vmap.VisualMemory.open(path, read_only=True).frames == 20
    # A with block left by an exception is a failed run: the old memory stays.
    with pytest.raises(RuntimeError, match="stopped"):
        with vmap.VisualMemory.create(path, force=True) as failed:
            failed.push(sample_frames[0][0])
            raise RuntimeError("stopped")
    assert vmap.VisualMemory.open(path, read_only=True).frames == 20
    assert [p.name for p in tmp_path.iterdir() if "vmap-new" in p.name] == []


def test_push_releases_the_gil(sample_list):
    mem = vmap.VisualMemory()
    worker = threading.Thread(target=mem.push_frames, args=(sample_list,))
    ticks = 0
    worker.start()
    while worker.is_alive():
        ticks += 1
        time.sleep(0.001)
    worker.join()
    assert mem.frames == 60
    # Held for the whole run, the GIL would have let this loop turn once or twice.
    assert ticks > 20


def test_camera_memory_gives_the_command_lines_relative_poses(tmp_path, shared, repo, vmap_cli):
    rgb = str(shared / "data" / "tum_fr1_rpy" / "rgb.txt")
    camera = str(repo / "examples" / "data" / "tum_fr1_camera.yaml")
    path = str(tmp_path / "cam.vmdb")
    with vmap.VisualMemory.create(path, camera=camera) as mem:
        mem.push_frames(rgb, end=120, stride=2)
        assert mem.stack["camera"]["fx"] > 0
    queries = [f for f in vmap.frames(rgb, grey=True, start=1, end=120, stride=12)]
    folder = (shared / "data" / "tum_fr1_rpy").resolve()
    answers = cli_json(vmap_cli, "memory", "localize", path, *[str(folder / "rgb" / n) for _, _, n in queries])["queries"]
    reader = vmap.VisualMemory.open(path, read_only=True)
    posed = 0
    for (img, _, _), answer in zip(queries, answers):
        got = reader.localize(img)
        assert got.status == answer["status"] and got.key == answer["key"]
        if answer["relative_pose"] is None:
            assert got.relative_pose is None
            continue
        posed += 1
        R = np.array(answer["relative_pose"]["rotation"]).reshape(3, 3)
        assert np.allclose(got.relative_pose.rotation, R, atol=1e-12)
        assert np.allclose(got.relative_pose.translation, answer["relative_pose"]["translation"], atol=1e-12)
        assert got.relative_pose.rotation_degrees < 10
        assert got.relative_pose.points_in_front == answer["relative_pose"]["points_in_front"]
    assert posed >= 5


def _tum_pose(row):
    """A TUM line's pose (tx ty tz qx qy qz qw) as a 4 x 4 camera-to-world matrix."""
    tx, ty, tz, x, y, z, w = row
    n = np.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    pose = np.eye(4)
    pose[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                    [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                    [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]
    pose[:3, 3] = tx, ty, tz
    return pose


def test_metric_pose_is_a_4x4_array_or_none_with_its_reason(tmp_path, shared, repo, sample_frames, vmap_cli):
    """Localization.pose: the query's camera-to-world pose in the memory's frame, as the
    command line's JSON gives it (TUM's quaternion order), or None and pose_reason."""
    truth = np.loadtxt(shared / "data" / "tum_fr1_rpy" / "groundtruth.txt")
    at = lambda t: _tum_pose(truth[np.abs(truth[:, 0] - t).argmin(), 1:])
    camera = str(repo / "examples" / "data" / "tum_fr1_camera.yaml")
    path = str(tmp_path / "metric.vmdb")
    with vmap.VisualMemory.create(path, camera=camera) as mem:
        for image, t, name in sample_frames[0::2]:
            mem.push(image, timestamp=t, name=name, pose=at(t))
    reader = vmap.VisualMemory.open(path, read_only=True)
    queries = sample_frames[1::6]
    posed = 0
    for image, t, name in queries:
        got = reader.localize(image)
        assert isinstance(got.pose_reason, str) and got.pose_reason
        if got.pose is None:
            assert got.pose_reason_code != "posed" and got.pose_covariance is None and got.pose_inliers is None
            continue
        posed += 1
        assert got.pose_reason_code == "posed"
        assert got.pose.shape == (4, 4) and got.pose.dtype == np.float64
        assert np.allclose(got.pose[3], [0, 0, 0, 1])
        assert np.allclose(got.pose[:3, :3] @ got.pose[:3, :3].T, np.eye(3), atol=1e-9)
        assert got.pose_covariance.shape == (6, 6)
        assert got.pose_inliers >= 12
        assert np.linalg.norm(got.pose[:3, 3] - at(t)[:3, 3]) < 0.05
    assert posed >= 7
    # The command line answers the same pose: position and quaternion (qx, qy, qz, qw).
    folder = (repo / "examples" / "data" / "tum_fr1_rpy_60").resolve()
    answers = cli_json(vmap_cli, "localize", "--memory", path, *[str(folder / "rgb" / n) for _, _, n in queries])["queries"]
    for (image, _, _), answer in zip(queries, answers):
        got = reader.localize(image)
        if got.pose is None:
            assert answer["pose"] is None and answer["pose_reason"] == got.pose_reason
            continue
        assert np.allclose(answer["pose"]["position"], got.pose[:3, 3], atol=1e-12)
        x, y, z, w = answer["pose"]["quaternion"]
        assert np.allclose(_tum_pose([0, 0, 0, x, y, z, w])[:3, :3], got.pose[:3, :3], atol=1e-9)
    # A memory without poses answers the key image and no pose, saying why.
    plain = vmap.VisualMemory(camera=camera)
    for image, t, name in sample_frames[0::2]:
        plain.push(image, timestamp=t, name=name)
    answer = plain.localize(queries[1][0])
    assert answer.ok and answer.pose is None and answer.pose_reason_code == "key image without a pose"


def test_fleet_robots_share_a_memory_on_postgresql(fleet_server, sample_frames, sample_list, vmap_cli, tmp_path):
    """Two robots write one fleet's memory with one vocabulary; the second finds the first's
    key images, and the fleet lists both robots and the loops between them."""
    uri = fleet_server("py_fleet")
    voc = tmp_path / "voc.bin"
    subprocess.run([vmap_cli, "vocabulary", sample_list, "--words", "512", "--depth", "3", "--out", str(voc)],
                   check=True, capture_output=True)
    found = []
    for robot in ("a", "b"):
        memory = vmap.VisualMemory.create(uri, robot=robot, vocabulary=str(voc))
        assert memory.robot == robot
        assert memory.path == uri
        for img, t, name in sample_frames:
            found += memory.push(img, timestamp=t, name=name).fleet_loops
        memory.close()
    robots = vmap.fleet_robots(uri)
    assert [r.robot for r in robots] == ["a", "b"]
    assert robots[0].key_images == robots[1].key_images > 5
    loops = vmap.fleet_loops(uri)
    # (those of the key images close() synced last are in the fleet only)
    assert 0 < len(found) <= len(loops)
    assert all(l.from_robot == "b" and l.to_robot == "a" for l in found)
    assert robots[1].fleet_loops == len(loops)
    again = vmap.VisualMemory.open(uri, robot="a", read_only=True)
    assert again.key_images == robots[0].key_images
    with pytest.raises(vmap.InvalidArgumentError, match="robot='NAME'"):
        vmap.VisualMemory.open(uri)
    with pytest.raises(vmap.NotFoundError, match="robot 'zed'"):
        vmap.VisualMemory.open(uri, robot="zed")
    with pytest.raises(vmap.UnavailableError):
        vmap.VisualMemory.open("postgresql://vmap@127.0.0.1:1/x?connect_timeout=2", robot="a")


def test_force_replaces_only_memories(tmp_path, sample_frames):
    # A user's SQLite database and a rosbag2 .db3 are SQLite files, not memories: never
    # replaced, with force or without (and without force, not called "the memory").
    import sqlite3

    for name in ("p.db", "bag.db3"):
        path = tmp_path / name
        con = sqlite3.connect(path)
        con.execute("create table t(x)")
        con.execute("insert into t values('mine')")
        con.commit()
        con.close()
        before = path.read_bytes()
        with pytest.raises(vmap.Error, match="is not a vmap memory") as raised:
            vmap.VisualMemory.create(str(path), force=True)
        assert "refusing to replace it" in str(raised.value)
        with pytest.raises(vmap.Error, match="exists and is not a vmap memory") as raised:
            vmap.VisualMemory.create(str(path))
        # Not called a memory, and force= not suggested (the whole message; the path
        # itself holds the test's name).
        assert str(raised.value) == f"'{path}' exists and is not a vmap memory; refusing to replace it"
        assert path.read_bytes() == before
    # An empty file has no records of a memory either.
    empty = tmp_path / "empty.vmdb"
    empty.write_bytes(b"")
    with pytest.raises(vmap.Error, match="is not a vmap memory"):
        vmap.VisualMemory.create(str(empty), force=True)
    assert empty.read_bytes() == b""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag.db3", "empty.vmdb", "p.db"]


def test_save_replaces_only_a_memory_file(tmp_path, sample_frames):
    mem = vmap.VisualMemory(vocabulary_after=5)
    for img, t, _ in sample_frames[:12]:
        mem.push(img, timestamp=t)
    notes = tmp_path / "notes.txt"
    notes.write_text("mine\n")
    with pytest.raises(vmap.Error, match="notes.txt' exists and is not a .vmem memory file; refusing to replace it"):
        mem.save(str(notes))
    assert notes.read_text() == "mine\n"
    store = tmp_path / "s.vmdb"
    with vmap.VisualMemory.create(str(store)) as s:
        for img, t, _ in sample_frames[:12]:
            s.push(img, timestamp=t)
    before = store.read_bytes()
    with pytest.raises(vmap.Error, match="s.vmdb' is a memory store"):
        mem.save(str(store))
    assert store.read_bytes() == before
    # A .vmem file is replaced, atomically.
    mem.save(str(tmp_path / "m.vmem"))
    mem.push(sample_frames[12][0], timestamp=sample_frames[12][1])
    mem.save(str(tmp_path / "m.vmem"))
    assert vmap.VisualMemory.open(str(tmp_path / "m.vmem")).frames == 13


def test_saving_an_open_store_over_itself_is_refused_and_later_pushes_stay(tmp_path, sample_frames):
    path = str(tmp_path / "s.vmdb")
    with vmap.VisualMemory.create(path) as s:
        for img, t, _ in sample_frames[:10]:
            s.push(img, timestamp=t)
    m = vmap.VisualMemory.open(path)
    with pytest.raises(vmap.Error, match="is a memory store"):
        m.save(path)
    for img, t, _ in sample_frames[10:13]:
        m.push(img, timestamp=t)
    m.close()
    again = vmap.VisualMemory.open(path, read_only=True)
    assert again.frames == 13 and again.path == path


def test_export_replaces_only_its_own_folder(tmp_path, sample_frames):
    mem = vmap.VisualMemory(vocabulary_after=5)
    for img, t, _ in sample_frames[:12]:
        mem.push(img, timestamp=t)
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "key_images.txt").write_text("my list\n")
    (folder / "notes.txt").write_text("mine\n")
    with pytest.raises(vmap.Error, match="holds files vmap did not write"):
        mem.export(str(folder))
    assert (folder / "key_images.txt").read_text() == "my list\n"
    assert sorted(p.name for p in folder.iterdir()) == ["key_images.txt", "notes.txt"]
    # A new folder, then the same again: an earlier export is replaced whole.
    out = tmp_path / "out"
    assert "key_images.txt" in mem.export(str(out))
    assert "key_images.txt" in mem.export(str(out))
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == ["key_images.txt", "loops.txt"]


def test_a_4x4_pose_must_be_homogeneous(sample_frames):
    mem = vmap.VisualMemory()
    bad = np.eye(4)
    bad[3] = [0.0, 0.0, 1.0, 1.0]
    with pytest.raises(vmap.Error, match="the last row of a 4 x 4 pose must be 0 0 0 1"):
        mem.push(sample_frames[0][0], pose=bad)
    assert mem.frames == 0
    good = np.eye(4)
    good[:3, 3] = [1.0, 2.0, 3.0]
    mem.push(sample_frames[0][0], pose=good)
    assert np.allclose(mem.keys[0]["pose"], good)
