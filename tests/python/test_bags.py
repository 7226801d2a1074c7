"""vmap.frames over robot bags (ROS 1, rosbag2 sqlite3, MCAP) and vmap.bag_info, against
the sample frames the shared bags were made from and against `vmap bag info`."""

import json
import subprocess

import numpy
import pytest

import vmap

TUM_BAGS = ["tum_fr1_rpy_60.bag", "tum_fr1_rpy_60_db3", "tum_fr1_rpy_60.mcap"]


@pytest.mark.parametrize("name", TUM_BAGS)
def test_frames_of_a_bag_equal_the_sample_frames(shared, sample_frames, name):
    frames = vmap.frames(str(shared / "data" / "bags" / name), grey=True, topic="/cam0/image_raw")
    got = list(frames)
    assert frames.kind == "bag"
    assert frames.topic == "/cam0/image_raw"
    assert frames.total == 60
    assert frames.camera is None
    assert frames.warnings == []
    assert len(got) == len(sample_frames) == 60
    for (image, timestamp, name_), (expected, expected_time, _) in zip(got, sample_frames):
        # mono8 is libjpeg's grey decoding of the same JPEG: equal to the pixel.
        assert numpy.array_equal(image, expected)
        assert timestamp == pytest.approx(expected_time, abs=1e-6)
        assert name_.startswith("/cam0/image_raw@")


def test_a_bag_with_several_image_topics_needs_a_topic(shared):
    bag = str(shared / "data" / "bags" / "tum_fr1_rpy_60.bag")
    with pytest.raises(vmap.Error, match="has 2 image topics: choose one"):
        vmap.frames(bag)
    with pytest.raises(vmap.Error, match="has no topic '/nope'"):
        vmap.frames(bag, topic="/nope")
    colour = list(vmap.frames(bag, topic="/camera/rgb/image_color"))
    assert len(colour) == 10 and colour[0][0].shape == (480, 640, 3)
    record = list(vmap.frames(bag, topic="/camera/rgb/image_color", record_time=True))
    assert [t for _, t, _ in record] == [t for _, t, _ in colour]  # written with record time = stamp


def test_bag_info_matches_the_command_line(shared, vmap_cli):
    for name in ["rtabmap_loop.mcap", "rtabmap_loop_db3", "rtabmap_loop_compressed.bag", "conformance/test_bag_mcap.mcap"]:
        bag = str(shared / "data" / "bags" / name)
        info = vmap.bag_info(bag)
        cli = json.loads(subprocess.run([vmap_cli, "bag", "info", bag, "--json"], check=True, capture_output=True, text=True).stdout)
        assert info["format"] == cli["format"]
        assert info["messages"] == cli["messages"]
        assert (info["start_ns"], info["end_ns"]) == (cli["start_ns"], cli["end_ns"])
        assert [(t["name"], t["type"], t["messages"]) for t in info["topics"]] == [
            (t["name"], t["type"], t["messages"]) for t in cli["topics"]]


def test_conformance_stub_images_are_skipped_with_their_reasons(shared):
    bag = str(shared / "data" / "bags" / "conformance" / "test_bag_sqlite3.db3")
    frames = vmap.frames(bag, topic="/test/sensor_msgs/image")
    assert frames.camera["fx"] == 525.0 and frames.camera["lens"] == "pinhole"
    with pytest.raises(vmap.Error, match="no frame of"):
        list(frames)
    assert len(frames.skipped) == 2
    assert "carries 30 bytes of pixels, rgb8 640x480 with step 1920 needs 921600" in frames.skipped[0][2]
    with pytest.raises(vmap.Error, match="holds sensor_msgs/msg/Imu, not images"):
        vmap.frames(bag, topic="/test/sensor_msgs/imu")


def test_inputs_that_are_fifos_are_refused_before_they_are_opened(tmp_path):
    import os
    import threading

    fifos = []
    for name in ["f.bag", "f.mcap", "f.db3", "f"]:
        os.mkfifo(tmp_path / name)
        fifos.append(tmp_path / name)
    done = threading.Event()

    def unblock():  # a reader that waits on a FIFO gets an empty file after 20 s: a failure, not a hang
        if done.wait(20):
            return
        while not done.is_set():
            for f in fifos:
                try:
                    os.close(os.open(f, os.O_WRONLY | os.O_NONBLOCK))
                except OSError:
                    pass
            done.wait(0.05)

    watchdog = threading.Thread(target=unblock)
    watchdog.start()
    try:
        for f in fifos:
            with pytest.raises(vmap.Error, match="is not a regular file or a folder"):
                vmap.frames(str(f))
            with pytest.raises(vmap.Error, match="is not a regular file or a folder"):
                vmap.bag_info(str(f))
    finally:
        done.set()
        watchdog.join()


def test_a_time_beyond_the_range_of_nanoseconds_is_refused(tmp_path):
    image = numpy.zeros((48, 64), numpy.uint8)
    memory = vmap.VisualMemory()
    with pytest.raises(vmap.Error, match=r"push: timestamp: time 1000000000000 s is beyond \+-9.2e9 s"):
        memory.push(image, timestamp=1e12)
    (tmp_path / "a.png").write_bytes(b"")
    (tmp_path / "far.txt").write_text("1.0 a.png\n1e10 a.png\n")
    with pytest.raises(vmap.Error, match=r"far.txt:2: time 10000000000 s is beyond"):
        vmap.frames(str(tmp_path / "far.txt"))
