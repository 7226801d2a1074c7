# Type stubs of examples/python/part_keyframes.cpp: the key-image selector (García-Pintos
# et al. 2023), its visual map and map files, and the threshold sweep. Features is the
# core part's class.

import os
from typing import Callable, Literal, Optional, Sequence, TypedDict, Union

import numpy
import numpy.typing as npt

_Path = Union[str, os.PathLike[str]]
_Status = Literal["verified", "too few matches", "no model", "too few inliers"]
_Reason = Literal[
    "similar to the key image",
    "first frame",
    "similarity below tau",
    "match bound below tau (verification skipped)",
    "verification failed",
]

class FrameResult:
    """What KeyframeSelector.push() did with one frame."""

    @property
    def frame_index(self) -> int: ...
    @property
    def similarity(self) -> float: ...
    @property
    def exact(self) -> bool: ...
    @property
    def raw_matches(self) -> int: ...
    @property
    def verified_matches(self) -> int: ...
    @property
    def status(self) -> _Status: ...
    @property
    def key_taken(self) -> bool: ...
    @property
    def key_frame(self) -> Optional[int]: ...
    @property
    def reason(self) -> _Reason: ...

class KeyImage:
    """One key image of a visual map."""

    @property
    def frame_index(self) -> int: ...
    @property
    def name(self) -> str: ...
    @property
    def timestamp(self) -> float: ...
    @property
    def features(self) -> Features: ...
    @property
    def image(self) -> Optional[npt.NDArray[numpy.generic]]: ...

class KeyPair:
    """The link between key image i and key image i+1."""

    @property
    def status(self) -> _Status: ...
    @property
    def fundamental(self) -> npt.NDArray[numpy.float64]: ...
    @property
    def matches(self) -> int: ...
    @property
    def inliers(self) -> int: ...
    @property
    def similarity(self) -> float: ...

class _MapStats(TypedDict):
    frames: int
    key_images: int
    min_matches: int
    max_matches: int
    mean_matches: float
    mean_similarity: float
    quality: float

class _SweepRow(_MapStats):
    threshold: float
    key_frames: list[int]
    best: bool

class VisualMap:
    """The key images of a video and the links between consecutive ones (a snapshot)."""

    @property
    def frames(self) -> int: ...
    @property
    def keys(self) -> list[KeyImage]: ...
    @property
    def pairs(self) -> list[KeyPair]: ...
    @property
    def key_frames(self) -> list[int]: ...
    @property
    def fundamentals(self) -> list[npt.NDArray[numpy.float64]]: ...
    @property
    def similarities(self) -> list[float]: ...
    def quality(self, form: Literal["mean_over_pairs", "paper_literal"] = "mean_over_pairs") -> float: ...
    def stats(self) -> _MapStats: ...
    def __len__(self) -> int: ...
    def __eq__(self, other: object) -> bool: ...

def save_map(map: VisualMap, path: _Path) -> None: ...
def load_map(path: _Path) -> VisualMap: ...

class KeyframeSelector:
    """Streaming key-image selection (García-Pintos et al. 2023, Algorithm 1 / eq. 6)."""

    def __init__(
        self,
        features: str = "orb",
        *,
        nfeatures: int = 1000,
        model: str = "",
        refine_model: str = "",
        estimator: str = "magsac",
        camera: Optional[str] = None,
        tau: float = 0.3,
        rule: Literal["previous", "current"] = "previous",
        skip_by_upper_bound: bool = True,
        keep_images: bool = False,
    ) -> None: ...
    def push(
        self, image: npt.NDArray[numpy.generic], timestamp: Optional[float] = None, name: Optional[str] = None
    ) -> FrameResult: ...
    def push_frames(
        self,
        source: str,
        *,
        start: int = 0,
        end: Optional[int] = None,
        stride: int = 1,
        time_offset: float = 0.0,
        single_thread: bool = False,
        progress: Optional[Callable[[int], object]] = None,
        progress_every: int = 50,
    ) -> list[FrameResult]: ...
    @property
    def map(self) -> VisualMap: ...
    def save_map(self, path: _Path) -> None: ...
    def reset(self) -> None: ...
    @property
    def tau(self) -> float: ...
    @property
    def rule(self) -> str: ...
    @property
    def features(self) -> str: ...
    @property
    def estimator(self) -> str: ...

def sweep(
    source: str,
    taus: Sequence[float] = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9),
    *,
    features: str = "orb",
    nfeatures: int = 1000,
    model: str = "",
    refine_model: str = "",
    estimator: str = "magsac",
    rule: Literal["previous", "current"] = "previous",
    camera: Optional[str] = None,
    start: int = 0,
    end: Optional[int] = None,
    stride: int = 1,
    time_offset: float = 0.0,
    single_thread: bool = False,
    progress: Optional[Callable[[int], object]] = None,
    progress_every: int = 50,
) -> list[_SweepRow]: ...
