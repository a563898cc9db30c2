"""The progress shown while rendering: a callable of the caller's, a tqdm bar when tqdm is
installed (tqdm.auto: a widget in Jupyter, text in a terminal), else a plain line on stderr
rewritten in place; nothing when asked to be silent."""

from __future__ import annotations

import sys
from typing import Any, Callable, Optional, Tuple


def _noop() -> None:
    return None


def make_progress(
    progress: Any, scene: Any, spp: Optional[int], time: Optional[float]
) -> Tuple[Optional[Callable[[dict], Any]], Callable[[], None]]:
    """The callback to hand to the native render, and what closes the display after it."""
    if progress is False:
        return None, _noop
    if callable(progress) and progress is not True:
        return progress, _noop
    try:
        from tqdm.auto import tqdm  # type: ignore[import-not-found]
    except ImportError:
        tqdm = None
    if tqdm is not None:
        bar = tqdm(total=1000, desc="flowlight", unit="‰", leave=False)

        def update_bar(p: dict) -> None:
            bar.n = int(1000 * p["fraction"])
            bar.set_postfix_str(f"{p['spp']:.1f} spp", refresh=False)
            bar.refresh()

        return update_bar, bar.close

    shown = [False]

    def update_line(p: dict) -> None:
        shown[0] = True
        sys.stderr.write(f"\rflowlight: {100 * p['fraction']:5.1f}%  {p['spp']:.1f} spp  {p['elapsed']:.1f} s")
        sys.stderr.flush()

    def close_line() -> None:
        if shown[0]:
            sys.stderr.write("\n")
            sys.stderr.flush()

    return update_line, close_line
