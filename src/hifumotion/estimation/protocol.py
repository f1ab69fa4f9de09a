"""Which frames train the model and which validate it.

The paper (Section 3.2) has ground truth every 10th step from the 20th: frames
20, 30, …, 100 train, 110, …, 190 validate — on a series of 200 frames. A series
of another length gets the same fractions of its length: training at 10 %,
15 %, …, 50 % of it, validation at 55 %, …, 95 % (exactly the paper's frames for 200).
"""

from __future__ import annotations

from hifumotion import paper
from hifumotion.errors import InputError


def default_frames(n_frames: int) -> tuple[list[int], list[int]]:
    """The paper's training and validation frames, scaled to ``n_frames``."""
    if n_frames < 20:
        raise InputError(f"a series of {n_frames} frames is too short for the paper's protocol (≥ 20)", "frames")
    train = sorted({int(round(n_frames * f / paper.SERIES_FRAMES)) for f in paper.TRAINING_FRAMES})
    valid = sorted({int(round(n_frames * f / paper.SERIES_FRAMES)) for f in paper.VALIDATION_FRAMES})
    return train, [v for v in valid if v < n_frames]


def parse_frames(text: str | list[int] | None, n_frames: int, what: str) -> list[int] | None:
    """``"20,30,40"`` or ``"20:101:10"`` (start:stop[:step]), or a list of frame numbers →
    sorted frame numbers; None passes through.

    The frames must lie in 1 … ``n_frames`` − 1; a range is checked by its ends before any
    list is made (``1:150000000`` is refused at once, not after allocating it).
    """
    if text is None:
        return None
    expected = f"expected frame numbers like '20,30,40' or '20:101:10', got {str(text)[:40]!r}"
    try:
        if not isinstance(text, str):
            frames = [int(p) for p in text]
        elif ":" in text:
            parts = [int(p) for p in text.split(":")]
            if len(parts) not in (2, 3):
                raise ValueError
            frames = range(*parts)
        else:
            frames = [int(p) for p in text.split(",") if p.strip()]
    except ValueError:
        raise InputError(expected, what) from None
    if not len(frames):
        raise InputError(f"{expected}: that is no frame", what)
    low, high = min(frames[0], frames[-1]), max(frames[0], frames[-1])
    if low < 1 or high > n_frames - 1:
        raise InputError(f"frames must lie in 1 … {n_frames - 1}; got {low} … {high}", what)
    return sorted(set(frames))


__all__ = ["default_frames", "parse_frames"]
