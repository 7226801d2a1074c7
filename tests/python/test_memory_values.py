"""vmap.VisualMemory refuses, where they enter, the values a memory could not keep;
push_frames numbers its frames after those already pushed; and calls from several
threads or from a progress callback leave a memory that reopens."""

import threading

import numpy as np
import pytest

import vmap


def test_bad_values_are_refused_and_the_store_still_reopens(tmp_path, sample_frames):
    path = str(tmp_path / "m.vmdb")
    mem = vmap.VisualMemory.create(path, vocabulary_after=5)
    for img, t, n in sample_frames[:10]:
        mem.push(img, timestamp=t, name=n)
    img = sample_frames[10][0]
    with pytest.raises(vmap.Error, match="the SE.3. pose is not finite"):
        mem.push(img, pose=np.full((3, 4), np.nan))
    with pytest.raises(vmap.Error, match="not a rotation"):
        mem.push(img, pose=np.hstack([2.0 * np.eye(3), np.zeros((3, 1))]))
    with pytest.raises(vmap.Error, match="pose: Pose2: x and y must be finite numbers"):
        mem.push(img, pose=(0.0, float("inf"), 0.0))
    with pytest.raises(vmap.Error, match="timestamp: time nan s is not finite"):
        mem.push(img, timestamp=float("nan"))
    with pytest.raises(vmap.Error, match="the name is 5000 bytes long"):
        mem.push(img, name="x" * 5000)
    with pytest.raises(vmap.Error, match="NUL"):
        mem.push(img, name="a\0b")
    with pytest.raises(vmap.Error, match="image: an image of 8193 x 8193 pixels, more than the limit of 67108864"):
        mem.push(np.zeros((8193, 8193), np.uint8))
    assert mem.frames == 10
    # Nothing refused reached the store: later pushes and syncs go on.
    for img, t, n in sample_frames[10:20]:
        mem.push(img, timestamp=t, name=n)
    mem.sync()
    mem.close()
    back = vmap.VisualMemory.open(path, read_only=True)
    assert back.frames == 20 and back.last_frame_index == 19


def test_push_frames_numbers_frames_after_those_pushed(tmp_path, sample_list, sample_frames):
    path = str(tmp_path / "m.vmdb")
    mem = vmap.VisualMemory.create(path, vocabulary_after=5)
    img, t, n = sample_frames[0]
    mem.push(img, timestamp=t, name=n)
    mem.push_frames(sample_list, end=10)          # source frames 0..9 follow frame 0
    assert mem.last_frame_index == 10
    mem.push_frames(sample_list, start=20, end=30)  # 20..29 follow frame 10 as they are
    assert mem.last_frame_index == 29
    mem.push_frames(sample_list, start=0, end=5)    # 0..4 shifted to follow frame 29
    assert mem.frames == 26 and mem.last_frame_index == 34
    mem.close()
    back = vmap.VisualMemory.open(path, read_only=True)
    assert back.frames == 26 and back.last_frame_index == 34
    # In a fresh memory (or a new session) the source's own indices are kept.
    fresh = vmap.VisualMemory(vocabulary_after=5)
    fresh.push_frames(sample_list, start=20, end=30)
    assert fresh.last_frame_index == 29


def test_threads_take_turns_and_callbacks_cannot_reenter(tmp_path, sample_list, sample_frames):
    path = str(tmp_path / "m.vmdb")
    mem = vmap.VisualMemory.create(path, vocabulary_after=5)
    errors = []

    def pusher(frames):
        try:
            for img, t, n in frames:
                mem.push(img, timestamp=t, name=n)
        except vmap.Error as e:  # pragma: no cover - reported below
            errors.append(str(e))

    threads = [threading.Thread(target=pusher, args=(sample_frames[k::2],)) for k in (0, 1)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    # Each push numbers its frame after the last one: 60 frames, whatever the order.
    assert errors == [] and mem.frames == 60 and mem.last_frame_index == 59

    inside = []

    def progress(done):
        for call in (mem.sync, lambda: mem.push(sample_frames[0][0]), mem.close):
            with pytest.raises(vmap.Error, match="busy in the same thread"):
                call()
        inside.append(done)

    mem.push_frames(sample_list, end=10, progress=progress, progress_every=5)
    assert inside == [5, 10]
    mem.close()
    back = vmap.VisualMemory.open(path, read_only=True)
    assert back.frames == 70


def test_an_array_changed_by_another_thread_during_push_is_not_read(sample_frames):
    # push copies the image before it lets other threads run: resizing the caller's
    # array meanwhile (NumPy frees the old buffer) does not reach the memory.
    mem = vmap.VisualMemory(vocabulary_after=5)
    img = np.array(sample_frames[0][0])
    stop = threading.Event()

    def resizer():
        while not stop.is_set():
            img.resize((10, 10), refcheck=False)
            img.resize(sample_frames[0][0].shape, refcheck=False)

    th = threading.Thread(target=resizer)
    th.start()
    try:
        for _ in range(30):
            try:
                mem.push(img)
            except vmap.Error:
                pass  # a 10 x 10 image, caught mid-resize, is refused as too small or empty
    finally:
        stop.set()
        th.join()
    assert mem.frames >= 1
