"""Small immutable pytree records without equinox, for the parse + FK path.

`Skeleton` and `FKResult` are all a user needs to read a BVH file and pose it. As equinox
modules they made that path import equinox and jaxtyping (about 0.1 s of a fresh process on 2
cores, a third of the first-call budget of issue 25). A `Record` behaves as those modules did
where fourierjax and its users rely on it: array fields are pytree leaves (traced, batched,
edited with `eqx.tree_at` or `jax.tree.map`), static fields travel in the tree structure,
instances are frozen, `==` compares structure and values, and the repr shows shapes.
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np


def _dtype(v):
    return v.dtype if hasattr(v, "dtype") else np.asarray(v).dtype


class Record:
    """Base of an immutable pytree record.

    A subclass names its array fields in `__leaves__` and its static (hashable) fields in
    `__static__`, sets them in `__init__` with `self._set(name, value)`, and checks them there.
    Unflattening (inside jit, vmap, grad) does not call `__init__`: leaves may be tracers or
    placeholders there.
    """

    __leaves__: tuple[str, ...] = ()
    __static__: tuple[str, ...] = ()

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        jax.tree_util.register_pytree_with_keys(
            cls, cls._flatten_with_keys, cls._unflatten, flatten_func=cls._flatten)

    def _set(self, name: str, value) -> None:
        object.__setattr__(self, name, value)

    def __setattr__(self, name, value):
        raise dataclasses.FrozenInstanceError(f"cannot assign to field {name!r}: {type(self).__name__} is immutable "
                                              "(make a new one, or use equinox.tree_at)")

    def __delattr__(self, name):
        raise dataclasses.FrozenInstanceError(f"cannot delete field {name!r}: {type(self).__name__} is immutable")

    def _flatten(self):
        return ([getattr(self, k) for k in self.__leaves__],
                tuple(getattr(self, k) for k in self.__static__))

    def _flatten_with_keys(self):
        return ([(jax.tree_util.GetAttrKey(k), getattr(self, k)) for k in self.__leaves__],
                tuple(getattr(self, k) for k in self.__static__))

    @classmethod
    def _unflatten(cls, static, leaves):
        obj = object.__new__(cls)
        for k, v in zip(cls.__leaves__, leaves):
            object.__setattr__(obj, k, v)
        for k, v in zip(cls.__static__, static):
            object.__setattr__(obj, k, v)
        return obj

    def __eq__(self, other):
        """Same type, same static fields, leaves of equal shape, dtype and values (a traced
        bool when a leaf is traced), as `equinox.tree_equal`."""
        if type(self) is not type(other):
            return NotImplemented
        a, tree_a = jax.tree_util.tree_flatten(self)
        b, tree_b = jax.tree_util.tree_flatten(other)
        if tree_a != tree_b:
            return False
        traced = []
        for x, y in zip(a, b):
            if x is None or y is None:
                if x is not y:
                    return False
                continue
            if np.shape(x) != np.shape(y) or _dtype(x) != _dtype(y):
                return False
            if isinstance(x, jax.core.Tracer) or isinstance(y, jax.core.Tracer):
                traced.append(jax.numpy.all(x == y))
            elif not np.array_equal(np.asarray(x), np.asarray(y)):
                return False
        return jax.numpy.all(jax.numpy.stack(traced)) if traced else True

    __hash__ = None  # type: ignore[assignment]  # array fields: not hashable (as equinox modules)

    def __repr__(self) -> str:
        def short(v):
            shape = getattr(v, "shape", None)
            dtype = getattr(v, "dtype", None)
            if shape is None or dtype is None:
                return repr(v)
            kind = np.dtype(dtype).kind
            letter = {"f": "f", "i": "i", "u": "u", "b": "bool", "c": "c"}.get(kind, str(dtype))
            bits = "" if letter == "bool" else str(np.dtype(dtype).itemsize * 8)
            return f"{letter}{bits}[{','.join(str(s) for s in shape)}]"

        fields = [f"{k}={short(getattr(self, k))}" for k in self.__leaves__]
        fields += [f"{k}={getattr(self, k)!r}" for k in self.__static__]
        return f"{type(self).__name__}({', '.join(fields)})"
