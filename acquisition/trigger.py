"""A start trigger in software, with pre-trigger samples, in front of any Device.

DAQmx keeps pre-trigger samples only for a reference trigger in a finite acquisition; a continuous
recording that must start on the tacho with some samples before it is triggered here instead:
the device runs untriggered, blocks are held back until ``channel`` crosses ``level_v`` with the
given edge, and the recording then starts ``pretrigger`` samples before the crossing (fewer if the
device had not produced that many). Row numbers in the recording start there: the wrapper re-bases
``first_index`` so the recorder sees a run starting at 0, and a second ``start`` event sits at the
trigger row (the first sample at or past the level), its detail saying so. A gap before the trigger only shortens the pre-trigger
part (held samples are contiguous); events before the kept part are dropped with it.
"""
from __future__ import annotations

import numpy as np

from labtool.acquisition.device import Block, Device, Event


def first_crossing(x: np.ndarray, level: float, edge: str, prev: float | None) -> int | None:
    """Index of the first sample of x at/above (rising) or at/below (falling) ``level`` whose
    predecessor (``prev`` for x[0]) was on the other side; None if there is none."""
    if x.size == 0:
        return None
    before = np.concatenate([[x[0] if prev is None else prev], x[:-1]])
    if edge == "rising":
        hit = (x >= level) & (before < level)
    else:
        hit = (x <= level) & (before > level)
    if prev is None:
        hit[0] = False  # no predecessor: an edge cannot be seen at the very first sample
    idx = np.flatnonzero(hit)
    return int(idx[0]) if idx.size else None


class SoftwareTrigger(Device):
    """Wraps ``inner``; see the module docstring. ``level_v`` in V on column ``channel``."""

    def __init__(self, inner: Device, channel: int, level_v: float, edge: str = "rising", pretrigger: int = 0):
        self.inner, self.channel, self.level_v, self.edge, self.pretrigger = inner, channel, level_v, edge, int(pretrigger)
        self.channel_names = inner.channel_names
        self._held: list[Block] = []
        self._offset = None  # device index of recording row 0, once triggered
        self._prev = None
        self.trigger_row = None
        self.metadata = {}

    def configure(self, rate_hz: float) -> float:
        rate = self.inner.configure(rate_hz)
        self.metadata = dict(getattr(self.inner, "metadata", {}) or {})
        self.metadata.update({"trigger_software": f"{self.edge} edge of {self.channel_names[self.channel]} through "
                                                  f"{self.level_v:g} V, {self.pretrigger} pre-trigger samples",
                              "pretrigger_samples": self.pretrigger})
        return rate

    @property
    def actual_rate_hz(self) -> float:
        return self.inner.actual_rate_hz

    @property
    def input_range_v(self):
        return self.inner.input_range_v

    def buffer_fill(self):
        return self.inner.buffer_fill()

    def start(self) -> None:
        self.inner.start()

    def stop(self) -> None:
        self.inner.stop()

    def describe(self) -> str:
        return self.inner.describe()

    def read_block(self) -> Block | None:
        while self._offset is None:
            block = self.inner.read_block()
            if block is None:
                return None
            self._hold(block)
        if self._held:
            out, self._held = self._held, []
            return _join(out)
        block = self.inner.read_block()
        if block is None:
            return None
        return Block(block.data, block.first_index - self._offset,
                     [Event(max(0, e.index - self._offset), e.kind, e.detail) for e in block.events])

    def _hold(self, block: Block) -> None:
        if self._held and block.first_index != self._held[-1].end_index:
            self._held, self._prev = [], None  # a gap: the held samples are no longer contiguous
        self._held.append(block)
        hit = first_crossing(np.asarray(block.data[:, self.channel], float), self.level_v, self.edge, self._prev)
        if block.n:
            self._prev = float(block.data[-1, self.channel])
        if hit is None:
            keep = self.pretrigger  # samples to keep for the pre-trigger part
            while len(self._held) > 1 and sum(b.n for b in self._held[1:]) >= keep:
                self._held.pop(0)
            return
        at = block.first_index + hit
        start = max(self._held[0].first_index, at - self.pretrigger)
        self._offset = start
        self.trigger_row = at - start
        kept = []
        for b in self._held:
            if b.end_index <= start:
                continue
            cut = max(0, start - b.first_index)
            kept.append(Block(b.data[cut:], b.first_index + cut - start,
                              [Event(max(0, e.index - start), e.kind, e.detail) for e in b.events if e.index >= start]))
        kept[0].events.insert(0, Event(self.trigger_row, "start", f"software trigger: {self.edge} edge of "
                                       f"{self.channel_names[self.channel]} through {self.level_v:g} V "
                                       f"({self.trigger_row} pre-trigger samples before this row)"))
        self._held = kept


def _join(blocks: list[Block]) -> Block:
    data = np.concatenate([b.data for b in blocks]) if blocks else np.empty((0, 0), np.float32)
    return Block(data, blocks[0].first_index, [e for b in blocks for e in b.events])
