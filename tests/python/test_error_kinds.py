"""vmap.Error's subclasses: one per kind of failure (vmap::ErrorKind), each also the
built-in exception a Python program already catches for it, raised by the real cause."""

import numpy
import pytest

import vmap

KINDS = {
    "InvalidArgumentError": ("invalid_argument", ValueError),
    "NotFoundError": ("not_found", FileNotFoundError),
    "CorruptError": ("corrupt", ValueError),
    "UnsupportedVersionError": ("unsupported_version", ValueError),
    "PolicyMismatchError": ("policy_mismatch", ValueError),
    "BusyError": ("busy", OSError),
    "IoError": ("io", OSError),
}


@pytest.mark.parametrize("name", sorted(KINDS))
def test_each_kind_is_an_error_and_its_builtin(name):
    cls = getattr(vmap, name)
    kind, builtin = KINDS[name]
    assert issubclass(cls, vmap.Error) and issubclass(cls, builtin) and issubclass(cls, RuntimeError)
    assert cls.kind == kind
    assert cls.__module__ == "vmap"


def test_a_missing_memory_is_not_found(tmp_path):
    with pytest.raises(vmap.NotFoundError, match="does not exist") as raised:
        vmap.VisualMemory.open(str(tmp_path / "none.vmem"))
    assert isinstance(raised.value, FileNotFoundError) and isinstance(raised.value, vmap.Error)
    with pytest.raises(FileNotFoundError):
        vmap.VisualMemory.open(str(tmp_path / "none.vmdb"))


def test_a_damaged_memory_is_corrupt_and_a_newer_one_unsupported(tmp_path):
    cut = tmp_path / "cut.vmem"
    cut.write_bytes(b"VMAPMEMO" + bytes(4))
    with pytest.raises(vmap.CorruptError):
        vmap.VisualMemory.open(str(cut), read_only=True)
    damaged = tmp_path / "damaged.vmdb"
    damaged.write_bytes(b"SQLite format 3\0" + b"m" * 4096)
    with pytest.raises(ValueError):
        vmap.VisualMemory.open(str(damaged), read_only=True)
    newer = tmp_path / "newer.vmem"
    newer.write_bytes(b"VMAPMEMO" + (99).to_bytes(4, "little") + bytes(64))
    with pytest.raises(vmap.UnsupportedVersionError, match="format version 99"):
        vmap.VisualMemory.open(str(newer), read_only=True)


def test_a_store_being_written_is_busy(tmp_path):
    path = str(tmp_path / "m.vmdb")
    writer = vmap.VisualMemory.create(path)
    with pytest.raises(vmap.BusyError, match="being written by another program") as raised:
        vmap.VisualMemory.open(path)
    assert isinstance(raised.value, OSError)
    writer.close()


def test_a_vocabulary_of_another_descriptor_is_a_policy_mismatch(sample_frames):
    orb = vmap.Descriptor("orb")
    vocabulary = vmap.Vocabulary.learn([orb.extract(image) for image, _, _ in sample_frames[:6]], branching=4, depth=2)
    floats = numpy.random.default_rng(7).random((80, 16), dtype=numpy.float32)
    with pytest.raises(vmap.PolicyMismatchError, match="the vocabulary's") as raised:
        vocabulary.transform(floats)
    assert isinstance(raised.value, ValueError)


def test_a_bad_option_is_an_invalid_argument():
    with pytest.raises(vmap.InvalidArgumentError, match="estimator"):
        vmap.VisualMemory(estimator="best")
    # Code written against vmap.Error alone keeps catching every kind.
    with pytest.raises(vmap.Error):
        vmap.VisualMemory(estimator="best")


def test_reason_code_names_the_case(sample_frames):
    empty = vmap.VisualMemory()
    answer = empty.localize(sample_frames[0][0])
    assert answer.reason_code == "the memory has no key image"
    assert answer.status == "too little evidence"
