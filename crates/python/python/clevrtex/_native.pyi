from typing import List, Optional, Tuple

import numpy as np

def score(
    truth: np.ndarray,
    pred: np.ndarray,
    no_background: bool,
    min_slots: int,
    pad_to_truth: bool,
    true_rgb: Optional[np.ndarray] = None,
    pred_rgb: Optional[np.ndarray] = None,
    truth_name: str = "true_masks",
    pred_name: str = "pred",
) -> List[Tuple[List[Optional[float]], List[float], List[int], Optional[List[float]]]]: ...
def metric_names() -> List[str]: ...
def protocol_metrics(protocol: str) -> List[str]: ...
def discover(
    path: str, variant: Optional[str] = None, split: str = "test"
) -> Tuple[str, List[Tuple[int, str, str, str]]]: ...
def colour_breakdown(variant: str) -> bool: ...
def read_metadata(path: str, root: str) -> bytes: ...
def load_sample(
    image: str, mask: str, crop: bool = True, side: Optional[int] = 128, root: Optional[str] = None
) -> Tuple[bytes, bytes, int, int]: ...
def load_item(
    image: str,
    mask: str,
    passes: List[Tuple[str, str]],
    crop: bool = True,
    side: Optional[int] = 128,
    root: Optional[str] = None,
) -> Tuple[bytes, bytes, int, int, Tuple[int, int], List[Tuple[str, bytes, int]]]: ...
def pass_files() -> List[Tuple[str, str, str]]: ...
def variant_names(
    variant: str,
    root: Optional[str] = None,
) -> Optional[Tuple[List[str], List[Tuple[str, float]], List[str], List[str]]]: ...
def id_tables(root: str) -> Tuple[List[str], List[str], List[str], List[str]]: ...
