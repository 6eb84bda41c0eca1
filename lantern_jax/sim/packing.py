"""A pytree as a few flat buffers, one per dtype: how states, scenarios and observations cross
the boundary between two compiled programs.

Calling a compiled program costs a few microseconds per argument and result array on the CPU
(measured in ``benchmarks/bench_iterate.py``: about 3 us per leaf), and a simulator state has
about 90 leaves, a scenario about 90 and an observation about 40.  A program that is called
once per tick (:mod:`lantern_jax.sim.split`) therefore takes and returns them packed: every
leaf of one item, ravelled, concatenated with the other leaves of its dtype.  Packing and
unpacking are slices, reshapes and one concatenation per dtype inside the program, and exact
(no dtype ever changes).

A :class:`Layout` describes ONE item (no batch axis); batches are ``vmap``-ed outside
(:meth:`Layout.pack`, :meth:`Layout.unpack`), or packed on the host with NumPy
(:meth:`Layout.pack_host`, :meth:`Layout.unpack_host`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

Array = jax.Array


@dataclasses.dataclass(frozen=True)
class Leaf:
    """Where one leaf lives in the packed buffers."""

    group: int  # index of its dtype's buffer
    offset: int  # first element in that buffer
    shape: tuple[int, ...]  # the leaf's shape (one item)

    @property
    def size(self) -> int:
        """Number of elements."""
        return int(np.prod(self.shape, dtype=np.int64))


@dataclasses.dataclass(frozen=True)
class Layout:
    """The packed form of one item of a pytree (see the module docstring).

    Attributes:
        treedef: the pytree's structure (static fields included).
        leaves: per leaf in ``jax.tree.leaves`` order, its :class:`Leaf`.
        groups: per buffer, ``(dtype name, number of elements)``, in order of first appearance.
    """

    treedef: Any
    leaves: tuple[Leaf, ...]
    groups: tuple[tuple[str, int], ...]

    @classmethod
    def of(cls, tree: Any) -> Layout:
        """The layout of ``tree`` (arrays or ``jax.ShapeDtypeStruct`` leaves of one item)."""
        leaves, treedef = jax.tree.flatten(tree)
        sizes: dict[str, list[int]] = {}
        out = []
        for x in leaves:
            dtype = np.dtype(jnp.result_type(x)).name
            shape = tuple(int(d) for d in np.shape(x))
            group = sizes.setdefault(dtype, [len(sizes), 0])
            out.append(Leaf(group[0], group[1], shape))
            group[1] += out[-1].size
        groups = tuple((dt, size) for dt, (_, size) in sizes.items())
        return cls(treedef, tuple(out), groups)

    @property
    def buffers(self) -> tuple[jax.ShapeDtypeStruct, ...]:
        """Shapes and dtypes of the packed buffers of one item."""
        return tuple(jax.ShapeDtypeStruct((size,), np.dtype(dt)) for dt, size in self.groups)

    def pack(self, tree: Any) -> tuple[Array, ...]:
        """One item's leaves as one flat buffer per dtype (traceable; ``vmap`` for a batch)."""
        leaves = jax.tree.leaves(tree)
        if len(leaves) != len(self.leaves):
            raise ValueError(f"Layout.pack: {len(leaves)} leaves, the layout has "
                             f"{len(self.leaves)}")  # fmt: skip
        parts: list[list[Array]] = [[] for _ in self.groups]
        for slot, x in zip(self.leaves, leaves, strict=True):
            parts[slot.group].append(jnp.ravel(x).astype(self.groups[slot.group][0]))
        return tuple(jnp.concatenate(p) for p in parts)

    def unpack(self, buffers: tuple[Array, ...]) -> Any:
        """The item packed in ``buffers`` (traceable; ``vmap`` for a batch)."""
        leaves = [
            jax.lax.slice_in_dim(buffers[s.group], s.offset, s.offset + s.size).reshape(s.shape)
            for s in self.leaves
        ]
        return jax.tree.unflatten(self.treedef, leaves)

    def pack_host(self, tree: Any) -> tuple[np.ndarray, ...]:
        """A batch (one leading axis on every leaf) packed with NumPy: ``(n, size)`` buffers."""
        leaves = [np.asarray(x) for x in jax.tree.leaves(tree)]
        n = leaves[0].shape[0] if leaves else 0
        parts: list[list[np.ndarray]] = [[] for _ in self.groups]
        for slot, x in zip(self.leaves, leaves, strict=True):
            parts[slot.group].append(x.reshape(n, -1).astype(self.groups[slot.group][0]))
        return tuple(np.concatenate(p, axis=1) for p in parts)

    def unpack_host(self, buffers: tuple[np.ndarray, ...]) -> Any:
        """The batch packed in ``(n, size)`` NumPy buffers, as the pytree (NumPy leaves)."""
        leaves = []
        for s in self.leaves:
            b = np.asarray(buffers[s.group])
            leaves.append(b[:, s.offset : s.offset + s.size].reshape((b.shape[0], *s.shape)))
        return jax.tree.unflatten(self.treedef, leaves)

    def index_of(self, path: str) -> Leaf:
        """The :class:`Leaf` of the leaf at ``path`` (``jax.tree_util.keystr`` form, e.g.
        ``".done"``).

        Raises:
            KeyError: naming the path when no leaf has it.
        """
        fake = jax.tree.unflatten(self.treedef, list(range(len(self.leaves))))
        for key, i in jax.tree_util.tree_flatten_with_path(fake)[0]:
            if jax.tree_util.keystr(key) == path:
                return self.leaves[i]
        raise KeyError(f"Layout: no leaf at {path!r}")
