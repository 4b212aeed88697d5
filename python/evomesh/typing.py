"""Type aliases of evomesh's public signatures (for annotations; runtime-valid on Python 3.9)."""

from __future__ import annotations

from typing import Callable, Mapping, Optional, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from evomesh.fronts import Front
from evomesh.mesh import Mesh

__all__ = ["ArrayLike", "NDArray", "FloatArray", "Distance", "Law", "FrontLike", "Fields"]

#: A float64 array.
FloatArray = NDArray[np.float64]
#: Distance from every mesh point to the front, or None for a step without a front.
Distance = Optional[FloatArray]
#: ``law(mesh, distance) -> delta`` (shape (n,)); a :class:`evomesh.SpacingLaw` is one.
Law = Callable[[Mesh, Distance], ArrayLike]
#: A :class:`evomesh.Front`, a callable ``t -> Front``, or None.
FrontLike = Union[Front, Callable[[float], Front], None]
#: Per-point fields by name, shape (n,) or (n, ...) each.
Fields = Mapping[str, ArrayLike]
