"""A braille canvas: each terminal cell is a 2 x 4 grid of dots, drawn with numpy, shown with rich.

Layers are drawn in order; a cell takes the style of the last layer that put a dot in it, and shows the
dots of every layer. Lines are rasterised by sampling points along every segment at once.
"""

from __future__ import annotations

import numpy as np
from rich.text import Text

# Dot (column, row) within a cell -> braille bit.
_BITS = np.array([[0x01, 0x02, 0x04, 0x40], [0x08, 0x10, 0x20, 0x80]], dtype=np.uint16)


class BrailleCanvas:
    def __init__(self, cols: int, rows: int):
        self.cols, self.rows = max(cols, 1), max(rows, 1)
        self.width, self.height = 2 * self.cols, 4 * self.rows  # in dots
        self._dots = np.zeros((self.height, self.width), dtype=bool)
        self._style = np.full((self.rows, self.cols), -1, dtype=np.int16)
        self._styles: list[str] = []

    def segments(self, start: np.ndarray, end: np.ndarray, style: str) -> None:
        """Lines from start[i] to end[i], in dot coordinates (x right, y down), (n, 2) each."""
        start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
        if len(start) == 0:
            return
        steps = np.maximum(np.abs(end - start).max(axis=1).astype(int), 1)
        total = int(steps.sum()) + len(steps)
        seg = np.repeat(np.arange(len(steps)), steps + 1)
        t = (np.arange(total) - np.repeat(np.cumsum(steps + 1) - (steps + 1), steps + 1)) / np.repeat(steps, steps + 1)
        pts = start[seg] + (end - start)[seg] * t[:, None]
        self.points(pts, style)

    def points(self, pts: np.ndarray, style: str) -> None:
        xy = np.rint(np.asarray(pts, dtype=float)).astype(int)
        ok = (xy[:, 0] >= 0) & (xy[:, 0] < self.width) & (xy[:, 1] >= 0) & (xy[:, 1] < self.height)
        x, y = xy[ok, 0], xy[ok, 1]
        if len(x) == 0:
            return
        self._dots[y, x] = True
        if style not in self._styles:
            self._styles.append(style)
        self._style[y // 4, x // 2] = self._styles.index(style)

    def render(self) -> Text:
        cells = self._dots.reshape(self.rows, 4, self.cols, 2)
        bits = (cells * _BITS.T[None, :, None, :]).sum(axis=(1, 3)).astype(np.uint32)
        chars = np.where(bits > 0, bits + 0x2800, 0x20)
        text = Text(no_wrap=True, overflow="crop")
        for r in range(self.rows):
            row, styles = chars[r], self._style[r]
            start = 0
            for c in range(1, self.cols + 1):
                if c == self.cols or styles[c] != styles[start]:
                    s = styles[start]
                    text.append("".join(map(chr, row[start:c])), self._styles[s] if s >= 0 else None)
                    start = c
            if r < self.rows - 1:
                text.append("\n")
        return text
