"""NLP parameters declared once, by name: packing (numeric) and unpacking (symbolic) are
generated from the declaration, never written out by position.

>>> decl = Parameters.of(shape=(1, 1), goal=(5, 1), vias=(5, 2))
>>> decl.size
16
>>> p = decl.pack(shape=[0.025], goal=np.zeros(5), vias=np.ones((5, 2)))
>>> parts = decl.unpack(ca.MX.sym("p", decl.size))  # {"shape": 1x1, "goal": 5x1, ...}

A matrix parameter is stored column by column (CasADi's ``vec``), and ``unpack`` gives it
back with its declared shape.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Parameters"]


@dataclass(frozen=True)
class Parameters:
    """An ordered declaration ``name -> (rows, cols)`` of an NLP's parameter vector."""

    fields: tuple[tuple[str, tuple[int, int]], ...]

    @staticmethod
    def of(**shapes: tuple[int, int]) -> Parameters:
        return Parameters(tuple((k, (int(r), int(c))) for k, (r, c) in shapes.items()))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(k for k, _ in self.fields)

    @property
    def size(self) -> int:
        return sum(r * c for _, (r, c) in self.fields)

    def offsets(self) -> dict[str, slice]:
        out: dict[str, slice] = {}
        start = 0
        for k, (r, c) in self.fields:
            out[k] = slice(start, start + r * c)
            start += r * c
        return out

    def unpack(self, p: Any) -> dict[str, Any]:
        """The named parts of a symbolic (or numeric) parameter vector, in their shapes."""
        shapes = dict(self.fields)
        return {k: ca.reshape(p[s.start:s.stop], *shapes[k])
                for k, s in self.offsets().items()}

    def pack(self, values: Mapping[str, ArrayLike] | None = None, **kw: ArrayLike
             ) -> NDArray[np.float64]:
        """The parameter vector of the named values (every declared name, each of its
        declared shape, or a vector of as many entries)."""
        given = {**(values or {}), **kw}
        missing = [k for k in self.names if k not in given]
        extra = [k for k in given if k not in self.names]
        if missing or extra:
            raise ValueError(f"parameters: missing {missing}, unknown {extra}")
        parts = []
        for k, (r, c) in self.fields:
            a = np.asarray(given[k], dtype=float)
            if a.size != r * c or (a.ndim == 2 and a.shape != (r, c)):
                raise ValueError(f"parameter {k!r} must be {r} x {c}, got shape {a.shape}")
            parts.append(a.reshape((r, c)).ravel(order="F") if a.ndim == 2 else a.ravel())
        return np.concatenate(parts) if parts else np.zeros(0)
