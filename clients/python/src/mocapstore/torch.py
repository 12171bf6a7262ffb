"""[`mocapstore.data.Windows`] for PyTorch: ``WindowDataset(windows)`` is a map-style
dataset for ``torch.utils.data.DataLoader`` (any ``num_workers``: each worker process
opens its own connection at its first window), and [`collate`] its ``collate_fn`` for
windows of different rigs. Needs the ``torch`` extra (see the README for the CPU wheel).

```python
loader = DataLoader(WindowDataset(windows), batch_size=32, shuffle=True, collate_fn=collate)
```
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from typing import Any

from . import data
from .data import Item, Windows


def _tensors(torch: Any, item: Item) -> dict[str, Any]:
    return {
        **item,
        "motion": torch.from_numpy(item["motion"]),
        "mask": torch.from_numpy(item["mask"]),
    }


class WindowDataset:
    """Window ``i`` as an [`Item`] whose ``motion`` ``(frames, points, 3)`` (0 where
    missing) and ``mask`` ``(frames, points)`` are tensors; ``len()`` windows."""

    def __init__(self, windows: Windows) -> None:
        self.windows = windows
        self._torch: Any = importlib.import_module("torch")

    def __len__(self) -> int:
        return len(self.windows)

    def __getitem__(self, i: int) -> dict[str, Any]:
        return _tensors(self._torch, self.windows[i])

    def __getitems__(self, indices: list[int]) -> list[dict[str, Any]]:
        """A DataLoader batch's windows in one request (or ``concurrency``): what the
        DataLoader calls, when a dataset has it, instead of one ``__getitem__`` each."""
        return [_tensors(self._torch, it) for it in self.windows.items(indices)]

    def __getstate__(self) -> dict[str, Any]:
        return {"windows": self.windows}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.windows = state["windows"]
        self._torch = importlib.import_module("torch")


def collate(items: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """A DataLoader's ``collate_fn``: [`mocapstore.data.collate`] (padded to the most
    points, mask False in the padding), ``motion`` and ``mask`` as tensors."""
    torch: Any = importlib.import_module("torch")
    as_numpy = [
        {**it, "motion": it["motion"].numpy(), "mask": it["mask"].numpy()}
        if hasattr(it["motion"], "numpy")
        else it
        for it in items
    ]
    return _tensors(torch, data.collate(as_numpy))
