"""vmap.frames, images in and out without copies, descriptors, features, matches, errors."""

import numpy as np
import pytest

import vmap


def test_frames_reads_the_sample_list(sample_list, sample_frames):
    with open(sample_list) as f:
        rows = [line.split() for line in f if line.strip() and not line.startswith("#")]
    assert len(sample_frames) == len(rows) == 60
    for (image, timestamp, name), (stamp, path) in zip(sample_frames, rows):
        assert image.shape == (480, 640) and image.dtype == np.uint8
        assert timestamp == pytest.approx(float(stamp), abs=1e-9)
        assert name == path.split("/")[-1]
    colour = next(iter(vmap.frames(sample_list, end=1)))[0]
    assert colour.shape == (480, 640, 3) and colour.dtype == np.uint8


def test_frames_options_and_properties(sample_list):
    frames = vmap.frames(sample_list, grey=True, start=10, end=20, stride=3, resize=(320, 240))
    assert frames.kind == "tum_rgb" and frames.total == 60  # the sequence's frames, before the range
    got = list(frames)
    assert [n for _, _, n in got] == [n for _, _, n in list(vmap.frames(sample_list, grey=True))[10:20:3]]
    assert all(img.shape == (240, 320) for img, _, _ in got)
    assert frames.delivered == 4 and frames.skipped == []


def test_frame_images_are_views_of_the_decoded_frame(sample_list):
    image = next(iter(vmap.frames(sample_list, grey=True)))[0]
    # The array does not own its pixels: it views the cv::Mat the source decoded.
    assert not image.flags.owndata and image.base is not None
    assert image.flags.c_contiguous


def test_images_are_read_in_place_or_copied_once():
    image = np.arange(48 * 64, dtype=np.uint8).reshape(48, 64)
    assert vmap.image_address(image) == image.ctypes.data
    rows = image[4:40]  # a row slice keeps whole rows: still in place
    assert vmap.image_address(rows) == rows.ctypes.data
    padded = np.zeros((48, 80), np.uint8)[:, :64]  # rows with a stride > width: in place
    assert vmap.image_address(padded) == padded.ctypes.data
    columns = image[:, ::2]  # pixels not contiguous within a row: copied
    assert vmap.image_address(columns) != columns.ctypes.data
    bgr = np.zeros((48, 64, 3), np.uint8)
    assert vmap.image_address(bgr) == bgr.ctypes.data
    deep = np.zeros((48, 64), np.uint16)
    assert vmap.image_address(deep) == deep.ctypes.data


def test_bad_images_raise_vmap_error():
    d = vmap.Descriptor("orb")
    with pytest.raises(vmap.Error, match="image: a float32 array; vmap reads uint8 or uint16"):
        d.extract(np.zeros((64, 64), np.float32))
    with pytest.raises(vmap.Error, match=r"image: an array of shape \(64, 64, 2\)"):
        d.extract(np.zeros((64, 64, 2), np.uint8))
    with pytest.raises(vmap.Error, match="image: an empty image"):
        d.extract(np.zeros((0, 64), np.uint8))
    assert issubclass(vmap.Error, RuntimeError)


def test_missing_input_names_it(tmp_path):
    missing = tmp_path / "nothing.txt"
    with pytest.raises(vmap.Error, match="nothing.txt"):
        vmap.frames(str(missing))


def test_descriptor_features_and_matches(sample_frames):
    orb = vmap.Descriptor("orb", nfeatures=500)
    assert orb.name == "orb" and orb.nfeatures == 500
    a = orb.extract(sample_frames[0][0])
    b = orb.extract(sample_frames[1][0])
    assert len(a) == a.keypoints.shape[0] == a.descriptors.shape[0] == 500
    assert a.keypoints.shape == (500, 6) and a.keypoints.dtype == np.float32
    assert a.descriptors.shape == (500, 32) and a.descriptors.dtype == np.uint8
    assert a.norm == "hamming" and a.image_size == (640, 480)
    # Keypoints lie inside the image.
    assert (a.keypoints[:, 0] >= 0).all() and (a.keypoints[:, 0] < 640).all()
    assert (a.keypoints[:, 1] >= 0).all() and (a.keypoints[:, 1] < 480).all()
    # Extraction is deterministic.
    again = orb.extract(sample_frames[0][0])
    assert np.array_equal(a.descriptors, again.descriptors) and np.array_equal(a.keypoints, again.keypoints)

    m = vmap.match(a, b)
    assert m.shape[1] == 3 and 100 < m.shape[0] <= 500
    q, t, dist = m[:, 0].astype(int), m[:, 1].astype(int), m[:, 2]
    # Each distance is the Hamming distance of the two descriptors, recomputed in NumPy.
    bits = np.unpackbits(a.descriptors[q] ^ b.descriptors[t], axis=1).sum(axis=1)
    assert np.array_equal(bits, dist.astype(int))
    # Mutual: every match is the nearest neighbour both ways (brute force in NumPy).
    table = np.unpackbits(a.descriptors[:, None, :] ^ b.descriptors[None, :, :], axis=2).sum(axis=2)
    assert (table[q, t] == table[q].min(axis=1)).all()
    assert (table[q, t] == table[:, t].min(axis=0)).all()
    assert len(set(q)) == len(q) and len(set(t)) == len(t)
    # The ratio test keeps a match only when clearly better than the second best.
    r = vmap.match(a, b, mode="ratio", ratio=0.7)
    for qi, ti, d in r:
        row = np.sort(table[int(qi)])
        assert d == row[0] and d < 0.7 * row[1]
    with pytest.raises(vmap.Error, match="mode must be 'mutual' or 'ratio'"):
        vmap.match(a, b, mode="nearest")


def test_float_descriptors(sample_frames):
    sift = vmap.Descriptor("sift", nfeatures=300)
    f = sift.extract(sample_frames[0][0])
    assert f.norm == "l2" and f.descriptors.dtype == np.float32 and f.descriptors.shape == (len(f), 128)
    assert 0 < len(f) <= 300


def test_unknown_descriptor_and_missing_model_raise_vmap_error():
    with pytest.raises(vmap.Error, match="unknown descriptor 'bogus'"):
        vmap.Descriptor("bogus")
    with pytest.raises(vmap.Error, match="xfeat needs model"):
        vmap.Descriptor("xfeat")


def test_xfeat_descriptor(shared, sample_frames):
    model = shared / "models" / "xfeat_320x224.onnx"
    if not model.exists():
        pytest.fail(f"{model} missing from the shared models")
    x = vmap.Descriptor("xfeat", nfeatures=256, model=str(model))
    f = x.extract(sample_frames[0][0])
    assert f.norm == "l2" and f.descriptors.shape == (len(f), 64) and 0 < len(f) <= 256
