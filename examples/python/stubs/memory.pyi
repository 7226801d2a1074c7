# Type stubs of examples/python/part_memory.cpp: the visual memory and its answers.

from types import TracebackType
from typing import Any, Callable, Literal, Optional, Sequence

import numpy
import numpy.typing as npt

_Pose = tuple[float, float, float] | npt.NDArray[numpy.float64] | None
_PlaceStatus = Literal["accepted", "unknown place", "ambiguous", "too little evidence"]
_PoseReason = Literal[
    "posed",
    "place not accepted",
    "no camera",
    "key image without a pose",
    "no baseline",
    "too few points",
    "few PnP inliers",
    "rotation disagrees",
    "uncertain",
    "moved by the sequence",
]

class PlaceEvidence:
    """What a place decision weighed (lcd/place_decision.hpp)."""

    @property
    def matches(self) -> int: ...
    @property
    def inliers(self) -> int: ...
    @property
    def inlier_ratio(self) -> float: ...
    @property
    def significance(self) -> float: ...
    @property
    def spread(self) -> float: ...
    @property
    def bow_score(self) -> float: ...
    @property
    def model(self) -> str: ...

class PlaceLink:
    """A verified match between a query (or a newer key image) and a key image."""

    @property
    def key(self) -> int: ...
    @property
    def bow_score(self) -> float: ...
    @property
    def status(self) -> str: ...
    @property
    def model(self) -> npt.NDArray[numpy.float64]: ...
    @property
    def model_kind(self) -> str: ...
    @property
    def matches(self) -> int: ...
    @property
    def inliers(self) -> int: ...
    @property
    def similarity(self) -> float: ...
    @property
    def confidence(self) -> float: ...

class LoopEdge:
    """A loop closure: key image `key_from` (the newer) revisits key image `key_to`."""

    @property
    def key_from(self) -> int: ...
    @property
    def key_to(self) -> int: ...
    @property
    def link(self) -> PlaceLink: ...

class FleetLoop:
    """A loop between two robots of a fleet's memory: key image `from_key` of robot `from_robot` shows the place of key image `to_key` of robot `to_robot`."""

    @property
    def from_robot(self) -> str: ...
    @property
    def from_key(self) -> int: ...
    @property
    def to_robot(self) -> str: ...
    @property
    def to_key(self) -> int: ...
    @property
    def link(self) -> PlaceLink: ...

class FleetRobot:
    """What a robot of a fleet's memory holds (vmap.fleet_robots)."""

    @property
    def robot(self) -> str: ...
    @property
    def frames(self) -> int: ...
    @property
    def key_images(self) -> int: ...
    @property
    def sessions(self) -> int: ...
    @property
    def loops(self) -> int: ...
    @property
    def fleet_loops(self) -> int: ...

def view(
    source: str,
    folder: str,
    *,
    robot: Optional[str] = None,
    image_side: int = 480,
    matches: bool = True,
    title: Optional[str] = None,
) -> dict[str, Any]: ...
def fleet_robots(uri: str) -> list[FleetRobot]: ...
def fleet_loops(uri: str) -> list[FleetLoop]: ...

class RelativePose:
    """The query's camera relative to a key image's: X_key = R X_query + t, |t| = 1."""

    @property
    def rotation(self) -> npt.NDArray[numpy.float64]: ...
    @property
    def translation(self) -> npt.NDArray[numpy.float64]: ...
    @property
    def rotation_degrees(self) -> float: ...
    @property
    def points_in_front(self) -> int: ...

class SequenceSupport:
    """What the neighbours of an image in a sequence added to its answer."""

    @property
    def window(self) -> int: ...
    @property
    def weighed(self) -> int:
        """The images of the window that see a place, this one included."""
    @property
    def on_line(self) -> int:
        """The images on the answer's line, each at a key image of its own (1: no line)."""
    @property
    def significance(self) -> float:
        """The line's combined significance (Fisher's method less the choice of line), or the image's own."""
    @property
    def single_confidence(self) -> float: ...
    @property
    def single_key(self) -> Optional[int]: ...

class Localization:
    """localize()'s answer: accepted, or why not, with the verified key images behind it."""

    @property
    def status(self) -> _PlaceStatus: ...
    @property
    def reason(self) -> str: ...
    @property
    def reason_code(self) -> _DecisionReason: ...
    @property
    def confidence(self) -> float: ...
    @property
    def evidence(self) -> PlaceEvidence: ...
    @property
    def ok(self) -> bool: ...
    @property
    def key(self) -> Optional[int]: ...
    @property
    def matches(self) -> list[PlaceLink]: ...
    @property
    def match_evidence(self) -> list[PlaceEvidence]: ...
    @property
    def sequence(self) -> Optional[SequenceSupport]: ...
    @property
    def verified_candidates(self) -> int: ...
    @property
    def relative_pose(self) -> Optional[RelativePose]: ...
    @property
    def pose(self) -> Optional[npt.NDArray[numpy.float64]]: ...
    @property
    def pose_covariance(self) -> Optional[npt.NDArray[numpy.float64]]: ...
    @property
    def pose_inliers(self) -> Optional[int]: ...
    @property
    def pose_reason(self) -> str: ...
    @property
    def pose_reason_code(self) -> _PoseReason: ...
    def __bool__(self) -> bool: ...

class MemoryStep:
    """What push() did: the selector's answer, the key image added, the loops found."""

    @property
    def frame_index(self) -> int: ...
    @property
    def similarity(self) -> float: ...
    @property
    def key_taken(self) -> bool: ...
    @property
    def key_frame(self) -> Optional[int]: ...
    @property
    def new_key(self) -> Optional[int]: ...
    @property
    def loops(self) -> list[LoopEdge]: ...
    @property
    def fleet_loops(self) -> list[FleetLoop]: ...

class PushSummary:
    """What push_frames did."""

    @property
    def pushed(self) -> int: ...
    @property
    def new_keys(self) -> int: ...
    @property
    def loops(self) -> list[LoopEdge]: ...
    @property
    def seconds(self) -> float: ...

class VisualMemory:
    """A visual memory: key images, loop closures and localization, in RAM or in a memory store."""

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
        images: Literal["none", "png", "jpeg"] = "none",
        vocabulary: Optional[str] = None,
        vocabulary_after: int = 20,
        min_confidence: float = 0.5,
        chance_inlier_rate: Optional[float] = None,
    ) -> None: ...
    @staticmethod
    def create(
        path: str,
        *,
        features: str = "orb",
        nfeatures: int = 1000,
        model: str = "",
        refine_model: str = "",
        estimator: str = "magsac",
        camera: Optional[str] = None,
        tau: float = 0.3,
        rule: Literal["previous", "current"] = "previous",
        images: Literal["none", "png", "jpeg"] = "none",
        vocabulary: Optional[str] = None,
        vocabulary_after: int = 20,
        min_confidence: float = 0.5,
        chance_inlier_rate: Optional[float] = None,
        force: bool = False,
        working_memory: int = 200,
        robot: Optional[str] = None,
    ) -> VisualMemory: ...
    @staticmethod
    def open(
        path: str,
        *,
        read_only: bool = False,
        new_session: bool = False,
        working_memory: int = 200,
        robot: Optional[str] = None,
    ) -> VisualMemory: ...
    def push(
        self,
        image: npt.NDArray[numpy.uint8] | npt.NDArray[numpy.uint16],
        *,
        timestamp: Optional[float] = None,
        name: Optional[str] = None,
        pose: _Pose = None,
    ) -> MemoryStep: ...
    def push_frames(
        self,
        source: str,
        *,
        grey: bool = True,
        start: int = 0,
        end: Optional[int] = None,
        stride: int = 1,
        resize: Optional[tuple[int, int]] = None,
        time_offset: float = 0.0,
        topic: Optional[str] = None,
        record_time: bool = False,
        poses: Optional[str] = None,
        progress: Optional[Callable[[int], object]] = None,
        progress_every: int = 50,
    ) -> PushSummary: ...
    def localize(
        self, image: npt.NDArray[numpy.uint8] | npt.NDArray[numpy.uint16], *, min_confidence: Optional[float] = None
    ) -> Localization: ...
    def localize_sequence(
        self,
        images: Sequence[npt.NDArray[numpy.uint8] | npt.NDArray[numpy.uint16]],
        *,
        window: int = 8,
        max_speed: float = 5.0,
        tolerance: int = 1,
        min_confidence: Optional[float] = None,
    ) -> list[Localization]: ...
    def localize_window(
        self,
        recent: Sequence[Localization] | Sequence[npt.NDArray[numpy.uint8] | npt.NDArray[numpy.uint16]],
        *,
        max_speed: float = 5.0,
        tolerance: int = 1,
        min_confidence: Optional[float] = None,
    ) -> Localization: ...
    def sync(self) -> None: ...
    def close(self) -> None: ...
    def __enter__(self) -> VisualMemory: ...
    def __exit__(
        self,
        exc_type: Optional[type[BaseException]],
        exc: Optional[BaseException],
        tb: Optional[TracebackType],
    ) -> None: ...
    def start_session(self) -> None: ...
    def save(self, path: str, *, images: Optional[Literal["none", "png", "jpeg"]] = None) -> None: ...
    def export(self, folder: str) -> list[str]: ...
    def view(
        self,
        folder: str,
        *,
        answers: Optional[Sequence[Localization | tuple[str, Localization]]] = None,
        image_side: int = 480,
        matches: bool = True,
        title: Optional[str] = None,
    ) -> dict[str, Any]: ...
    @property
    def path(self) -> Optional[str]: ...
    @property
    def robot(self) -> Optional[str]: ...
    @property
    def read_only(self) -> bool: ...
    @property
    def stack(self) -> dict[str, Any]: ...
    @property
    def stack_text(self) -> str: ...
    @property
    def frames(self) -> int: ...
    @property
    def key_images(self) -> int: ...
    @property
    def last_frame_index(self) -> Optional[int]: ...
    @property
    def stationary(self) -> bool: ...
    @property
    def vocabulary_words(self) -> int: ...
    @property
    def loops(self) -> list[LoopEdge]: ...
    @property
    def sessions(self) -> list[dict[str, int]]: ...
    @property
    def keys(self) -> list[dict[str, Any]]: ...
    def key_image(self, key: int) -> Optional[npt.NDArray[numpy.uint8]]: ...
    def key_features(self, key: int) -> Features: ...
    def neighbours(self, key: int) -> list[tuple[int, Literal["link", "loop"]]]: ...
