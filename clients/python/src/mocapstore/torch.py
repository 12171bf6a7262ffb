"""[`mocapstore.data.Windows`] for PyTorch: ``WindowDataset(windows)`` is a map-style
dataset for ``torch.utils.data.DataLoader`` (any ``num_workers``: each worker process
opens its own connection at its first window). Needs the ``torch`` extra."""

from __future__ import annotations

import importlib
from typing import Any

from .data import Windows


class WindowDataset:
    """Window ``i`` as a float32 tensor ``(frames, points, 3)``, NaN where missing (mask
    with ``torch.isnan``); ``len()`` windows."""

    def __init__(self, windows: Windows) -> None:
        self.windows = windows
        self._torch: Any = importlib.import_module("torch")

    def __len__(self) -> int:
        return len(self.windows)

    def __getitem__(self, i: int) -> Any:
        return self._torch.from_numpy(self.windows[i])

    def __getitems__(self, indices: list[int]) -> list[Any]:
        """A DataLoader batch's windows in one request (or ``concurrency``): what the
        DataLoader calls, when a dataset has it, instead of one ``__getitem__`` each."""
        return [self._torch.from_numpy(a) for a in self.windows.many(indices)]

    def __getstate__(self) -> dict[str, Any]:
        return {"windows": self.windows}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.windows = state["windows"]
        self._torch = importlib.import_module("torch")
