from typing import List, Optional, Tuple

def score(
    truth: bytes,
    pred: bytes,
    batch: int,
    pixels: int,
    masks: int,
    no_background: bool,
    min_slots: int,
    true_rgb: Optional[bytes] = None,
    pred_rgb: Optional[bytes] = None,
) -> List[Tuple[List[Optional[float]], List[float], List[int], Optional[List[float]]]]: ...
def metric_names() -> List[str]: ...
def protocol_metrics(protocol: str) -> List[str]: ...
def discover(
    path: str, variant: Optional[str] = None, split: str = "test"
) -> Tuple[str, List[Tuple[int, str, str, str]]]: ...
def load_sample(
    image: str, mask: str, crop: bool = True, side: Optional[int] = 128
) -> Tuple[bytes, bytes, int, int]: ...
