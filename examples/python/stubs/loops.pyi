# Stubs of part_loops.cpp: loop closure (detect_loops, LoopDetector) and its evaluation.
# `Features` is part_core's class.
import os
from typing import Callable, Optional, Sequence, Tuple, Union

import numpy
import numpy.typing as npt

_Path = Union[str, os.PathLike[str]]
# Per frame: rows (label, score, x, y, w, h), box in pixels.
_Detections = Union[Sequence[Sequence[float]], npt.NDArray[numpy.floating]]

class Loop:
    """One loop found: query frame -> matched (older) frame, with its evidence."""
    @property
    def query(self) -> int: ...
    @property
    def match(self) -> int: ...
    @property
    def query_name(self) -> str: ...
    @property
    def match_name(self) -> str: ...
    @property
    def query_time(self) -> float: ...
    @property
    def match_time(self) -> float: ...
    @property
    def confidence(self) -> float: ...
    @property
    def inliers(self) -> int: ...
    @property
    def matches(self) -> int: ...
    @property
    def inlier_ratio(self) -> float: ...
    @property
    def significance(self) -> float: ...
    @property
    def spread(self) -> float: ...
    @property
    def bow_score(self) -> float: ...

class LoopDecision:
    """The loop engine's answer for one frame: status, reason, confidence and best verified frame."""
    @property
    def frame(self) -> int: ...
    @property
    def loop(self) -> bool: ...
    @property
    def status(self) -> str:
        """accepted, unknown place, ambiguous, too little evidence or not a revisit"""
    @property
    def reason(self) -> str: ...
    @property
    def reason_code(self) -> _DecisionReason: ...
    @property
    def confidence(self) -> float: ...
    @property
    def best(self) -> Optional[int]: ...
    @property
    def second(self) -> Optional[int]: ...
    @property
    def second_confidence(self) -> float: ...
    @property
    def inliers(self) -> int: ...
    @property
    def matches(self) -> int: ...
    @property
    def inlier_ratio(self) -> float: ...
    @property
    def significance(self) -> float: ...
    @property
    def spread(self) -> float: ...
    @property
    def bow_score(self) -> float: ...
    @property
    def candidates(self) -> int: ...
    @property
    def verifications(self) -> int: ...
    @property
    def failed_verifications(self) -> int: ...
    @property
    def consistent_queries(self) -> int: ...
    @property
    def labels(self) -> list[int]: ...
    @property
    def considered(self) -> list[Tuple[int, float, int, float, str]]:
        """(frame, bow_score, inliers, confidence, stage) of each candidate ranked or verified"""
    @property
    def rank_ms(self) -> float: ...
    @property
    def verify_ms(self) -> float: ...
    @property
    def decide_ms(self) -> float: ...

class LoopRun:
    """The result of detect_loops: the loops, every frame's decision and the run's figures."""
    @property
    def loops(self) -> list[Loop]: ...
    @property
    def decisions(self) -> list[LoopDecision]: ...
    @property
    def frames(self) -> int: ...
    @property
    def names(self) -> list[str]: ...
    @property
    def times(self) -> list[float]: ...
    @property
    def skipped_frames(self) -> int: ...
    @property
    def rank(self) -> str:
        """the candidate source: tree, tree_ranked, bow or brute_force"""
    @property
    def min_confidence(self) -> float: ...
    @property
    def chance_inlier_rate(self) -> float:
        """the decision's chance-inlier rate (the stack's measured one unless given)"""
    @property
    def window(self) -> int: ...
    @property
    def verifications(self) -> int: ...
    @property
    def stationary(self) -> bool: ...
    @property
    def seconds(self) -> float: ...
    @property
    def labels_kept(self) -> list[int]: ...
    @property
    def scores(self) -> npt.NDArray[numpy.float64]:
        """N x 3: query, best match (-1: none), score"""
    def __len__(self) -> int: ...

class Evaluation:
    """Precision and recall of loop closure against ground truth."""
    @property
    def precision(self) -> float: ...
    @property
    def recall(self) -> float: ...
    @property
    def true_positives(self) -> int: ...
    @property
    def false_positives(self) -> int: ...
    @property
    def false_negatives(self) -> int: ...
    @property
    def positives(self) -> int: ...
    @property
    def frames(self) -> int: ...
    @property
    def threshold(self) -> float: ...
    @property
    def recall_at_100_precision(self) -> float: ...
    @property
    def threshold_at_100_precision(self) -> Optional[float]: ...
    @property
    def curve(self) -> npt.NDArray[numpy.float64]:
        """K x 5: threshold, precision, recall, true positives, false positives"""
    @property
    def ground_truth(self) -> npt.NDArray[numpy.bool_]: ...

class LoopDetector:
    """The loop detector fed one frame at a time."""
    def __init__(
        self,
        *,
        features: str = "orb",
        nfeatures: int = 1000,
        model: str = "",
        refine_model: str = "",
        vocabulary: Union[_Path, Sequence[Features], None] = None,
        words: int = 1000,
        depth: int = 3,
        seed: int = 1,
        label_order: Optional[Sequence[int]] = None,
        rank: Optional[str] = None,
        window: int = 10,
        min_candidates: int = 5,
        top_k: int = 2,
        min_bow_score: float = 0.0,
        temporal_consistency: int = 0,
        temporal_tolerance: int = 3,
        left_ratio: float = 0.5,
        min_confidence: float = 0.5,
        min_inliers: int = 12,
        chance_inlier_rate: Optional[float] = None,
        half_significance: float = 12.0,
        spread_grid: int = 4,
        full_spread: float = 0.35,
        ambiguity_ratio: float = 0.9,
        label_min_score: float = 0.5,
    ) -> None: ...
    def add(
        self, frame: Union[npt.NDArray[numpy.uint8], npt.NDArray[numpy.uint16], Features], detections: Optional[_Detections] = None
    ) -> LoopDecision: ...
    @property
    def frames(self) -> int: ...
    @property
    def verifications(self) -> int: ...
    @property
    def stationary(self) -> bool: ...
    @property
    def memory_bytes(self) -> int: ...
    @property
    def rank(self) -> str:
        """the candidate source: tree, tree_ranked, bow or brute_force"""
    @property
    def features(self) -> str: ...
    @property
    def window(self) -> int: ...
    @property
    def min_confidence(self) -> float: ...
    @property
    def chance_inlier_rate(self) -> float:
        """the decision's chance-inlier rate (the stack's measured one unless given)"""
    def __len__(self) -> int: ...

def detect_loops(
    source: Union[_Path, Sequence[npt.NDArray[numpy.uint8]], Sequence[npt.NDArray[numpy.uint16]], Sequence[Features]],
    *,
    features: str = "orb",
    nfeatures: int = 1000,
    model: str = "",
    refine_model: str = "",
    labels: Union[_Path, Sequence[_Path], Sequence[_Detections], None] = None,
    rank: Optional[str] = None,
    vocabulary: Optional[_Path] = None,
    words: int = 1000,
    depth: int = 3,
    seed: int = 1,
    window: int = 10,
    min_candidates: int = 5,
    top_k: int = 2,
    min_bow_score: float = 0.0,
    temporal_consistency: int = 0,
    temporal_tolerance: int = 3,
    left_ratio: float = 0.5,
    min_confidence: float = 0.5,
    min_inliers: int = 12,
    chance_inlier_rate: Optional[float] = None,
    half_significance: float = 12.0,
    spread_grid: int = 4,
    full_spread: float = 0.35,
    ambiguity_ratio: float = 0.9,
    label_min_score: float = 0.5,
    min_influence: float = 0.05,
    max_influence: float = 0.95,
    label_order: Optional[Sequence[int]] = None,
    sample: int = 0,
    time_offset: float = 0.0,
    progress: Optional[Callable[[str, int, int], object]] = None,
) -> LoopRun: ...
class ChanceCalibration:
    @property
    def rate(self) -> float:
        """the chance-inlier rate: give it as chance_inlier_rate"""
    @property
    def pairs(self) -> int:
        """foreign pairs verified"""
    @property
    def weighed(self) -> int:
        """of those, with at least 12 inliers"""
    @property
    def strongest_significance(self) -> float:
        """the strongest foreign pair's significance at the rate"""

def calibrate_chance_rate(
    places: Sequence[_Path],
    *,
    features: str = "orb",
    nfeatures: int = 1000,
    model: str = "",
    refine_model: str = "",
    estimator: str = "magsac",
    pairs: int = 200,
    seed: int = 1,
) -> ChanceCalibration: ...
def measured_chance_rate(features: str = "orb") -> float: ...
def evaluate(
    loops: Union[LoopRun, npt.NDArray[numpy.floating], Sequence[Tuple[int, Optional[int], float]]],
    ground_truth: Union[_Path, npt.NDArray[numpy.bool_], npt.NDArray[numpy.integer], None] = None,
    *,
    poses: Union[_Path, npt.NDArray[numpy.floating], None] = None,
    max_distance: float = 0.5,
    max_angle: float = 30.0,
    window: Optional[int] = None,
    min_confidence: Optional[float] = None,
) -> Evaluation: ...
