# Type stubs of examples/python/module.cpp and part_core.cpp: vmap.Error, frame sources,
# images, descriptors, features and matches.

from typing import Any, Iterator, Literal, Optional

import numpy
import numpy.typing as npt

__version__: str

_Image = npt.NDArray[numpy.uint8] | npt.NDArray[numpy.uint16]

_DecisionReason = Literal[
    "no candidates",
    "every candidate below the bag-of-words score",
    "no candidate verified",
    "too few inliers",
    "not yet confirmed",
    "the memory has no key image",
    "the query image has no features",
    "the camera never left the candidates' place",
    "confidence below the threshold",
    "two places equally likely",
    "confidence reaches the threshold",
]

class Error(RuntimeError):
    """A bad input (a file, an image, an option value) or a failed step, with vmap's message.
    Its subclasses say which kind of failure it is (their attribute `kind`)."""

class InvalidArgumentError(Error, ValueError):
    """A bad option, value or call: the caller must change it."""
    kind: str

class NotFoundError(Error, FileNotFoundError):
    """A file or folder that does not exist."""
    kind: str

class CorruptError(Error, ValueError):
    """A file that exists but is damaged or is not of its format."""
    kind: str

class UnsupportedVersionError(Error, ValueError):
    """A file of a newer format version than this build reads."""
    kind: str

class PolicyMismatchError(Error, ValueError):
    """A memory or vocabulary made with other policies (descriptor, stack, options)."""
    kind: str

class BusyError(Error, OSError):
    """A memory store another program writes (one writer at a time)."""
    kind: str

class IoError(Error, OSError):
    """A write, flush or rename the system refused (a full disk, permissions)."""
    kind: str

class UnavailableError(Error, ConnectionError):
    """A database server (a fleet's memory) that cannot be reached or went away: try again later."""
    kind: str

class Frames:
    """The frames of a source, as (image, timestamp, name) tuples (vmap.frames)."""

    def __iter__(self) -> Frames: ...
    def __next__(self) -> tuple[npt.NDArray[numpy.uint8], float, str]: ...
    @property
    def kind(self) -> Literal["video", "image_folder", "image_list", "tum_rgb", "live", "euroc", "bag"]: ...
    @property
    def total(self) -> Optional[int]: ...
    @property
    def delivered(self) -> int: ...
    @property
    def skipped(self) -> list[tuple[int, str, str]]: ...
    @property
    def topic(self) -> Optional[str]: ...
    @property
    def camera(self) -> Optional[dict[str, Any]]: ...
    @property
    def warnings(self) -> list[str]: ...

def frames(
    source: str,
    *,
    grey: bool = False,
    start: int = 0,
    end: Optional[int] = None,
    stride: int = 1,
    resize: Optional[tuple[int, int]] = None,
    time_offset: float = 0.0,
    topic: Optional[str] = None,
    record_time: bool = False,
) -> Frames: ...
def bag_info(bag: str) -> dict[str, Any]: ...
def image_address(image: _Image) -> int: ...

class Features:
    """Keypoints and their descriptors, as NumPy arrays."""

    @property
    def keypoints(self) -> npt.NDArray[numpy.float32]: ...
    @property
    def descriptors(self) -> npt.NDArray[numpy.uint8] | npt.NDArray[numpy.float32]: ...
    @property
    def norm(self) -> Literal["hamming", "l2"]: ...
    @property
    def image_size(self) -> tuple[int, int]: ...
    def __len__(self) -> int: ...

class Descriptor:
    """A feature descriptor chosen by name: orb, akaze, sift, xfeat, xfeat-dense or xfeat-star."""

    def __init__(
        self, features: str = "orb", *, nfeatures: int = 1000, model: str = "", refine_model: str = ""
    ) -> None: ...
    def extract(self, image: _Image) -> Features: ...
    @property
    def name(self) -> str: ...
    @property
    def nfeatures(self) -> int: ...

def match(
    a: Features, b: Features, *, mode: Literal["mutual", "ratio"] = "mutual", ratio: float = 0.8
) -> npt.NDArray[numpy.float32]: ...
