"""Saved programs: jitted functions traced and lowered once, kept on disk (`jax.export`) for later runs."""

from __future__ import annotations

import contextlib
import functools
import hashlib
import logging
import pathlib
import pickle
import re
import threading
from collections.abc import Callable

_log = logging.getLogger(__name__)

#: Bumped when the file layout below changes: older files are then ignored.
FORMAT = 1
_MAGIC = b"fourierjax-saved-program\n"


def saved(fun: Callable, *, cpu_compiler_options: dict | None = None) -> Callable:
    """Wrap a jitted pure function so that its program is read from disk on later runs.

    The persistent compile cache (`fourierjax._compile_cache`) skips XLA's compile, but not
    the trace and lowering that come before it, which cost most of a warm command line call
    for the large programs (a fit chunk, a gait synthesis, a stance problem). A call of the
    wrapped function at the top level (outside any transformation), with the cache on, looks
    for a serialized `jax.export.Exported` in `_compile_cache.saved_dir()`, keyed by the
    function's qualified name, the static arguments and input tree, the shapes and dtypes of
    the array arguments, the fourierjax version and a hash of the package's source files, the
    jax and jaxlib versions, the backend and the configuration that changes a trace (x64,
    matmul precision). Found: it is deserialized and compiled (a persistent cache hit). Not
    found: the function is exported, saved atomically (a temporary file, then a rename) and
    called. The result is the one program either way.

    The arguments follow `equinox.filter_jit`: array leaves (JAX and NumPy arrays and NumPy
    scalars) are inputs; every other leaf (Python numbers included) is static and part of the
    key. Pytrees are flattened at the boundary, so custom pytree classes need no serialization
    registration; the output's structure is saved as the output with its leaves replaced by
    their positions. A file that cannot be read or used (corrupt, another format, a key that
    does not match) is ignored, with a debug log, and replaced. A function that cannot be
    exported (host callbacks, e.g. `equinox.error_if`) runs as the plain jitted function.
    Unless `_compile_cache.enable_compile_cache` turned the cache on (every command line call
    does), or with ``$FOURIERJAX_NO_CACHE`` set (``fourierjax --no-cache``), the wrapper is the
    plain function and writes nothing. Forward calls only (no vjp is saved).

    Arguments:
        fun: a jitted function (e.g. from `fourierjax._jit.filter_jit`); it is also what runs
            inside transformations and when the cache is off.
        cpu_compiler_options: the XLA:CPU options the program is compiled with (default: the
            ones `fourierjax._jit.filter_jit` uses), so that it is the same executable.

    Returns:
        The wrapped function, with ``.stats`` (a dict counting ``"loaded"``, ``"exported"``,
        ``"plain"`` calls and ``"rejected"`` files of this process) and ``.fun``.
    """
    programs: dict[str, tuple[Callable, object]] = {}
    unexportable: set[str] = set()
    stats = {"loaded": 0, "exported": 0, "plain": 0, "rejected": 0}
    name = f"{getattr(fun, '__module__', '?')}.{getattr(fun, '__qualname__', repr(fun))}"

    @functools.wraps(fun)
    def wrapper(*args, **kwargs):
        from fourierjax import _compile_cache, _jit

        if not _compile_cache.saved_programs_on() or not _jit._trace_state_clean():
            stats["plain"] += 1
            return fun(*args, **kwargs)
        import jax

        leaves, treedef = jax.tree.flatten((args, kwargs))
        dynamic = [_is_array(x) for x in leaves]
        if not any(dynamic):
            stats["plain"] += 1
            return fun(*args, **kwargs)
        arrays = [x for x, d in zip(leaves, dynamic, strict=True) if d]
        static = [None if d else x for x, d in zip(leaves, dynamic, strict=True)]
        specs = [jax.ShapeDtypeStruct(x.shape, jax.dtypes.canonicalize_dtype(x.dtype),
                                      weak_type=bool(getattr(x, "weak_type", False)))
                 for x in arrays]
        # A hashable key first (no text to build on a repeated call, e.g. the explorer's).
        fast = _fast_key(treedef, static, specs)
        entry = None if fast is None else programs.get(fast)
        key = None
        if entry is None:
            key = _key_text(name, treedef, static, specs)
            if key is None or key in unexportable:
                stats["plain"] += 1
                return fun(*args, **kwargs)
            entry = programs.get(key)
        if entry is None:
            path = _path(name, key)
            entry = _load(path, key, specs, cpu_compiler_options)
            if entry is None:
                if path.exists():
                    stats["rejected"] += 1
                entry = _export(fun, treedef, static, dynamic, specs, path, key,
                                cpu_compiler_options)
                if entry is None:
                    unexportable.add(key)
                    stats["plain"] += 1
                    return fun(*args, **kwargs)
                stats["exported"] += 1
            else:
                stats["loaded"] += 1
            programs[key] = entry
        if fast is not None and key is not None:
            programs[fast] = entry
        runner, out_skeleton = entry
        outs = runner(*arrays)
        out_leaves, out_tree = jax.tree.flatten(out_skeleton)
        return jax.tree.unflatten(out_tree, [outs[i] for i in out_leaves])

    wrapper.stats = stats  # type: ignore[attr-defined]
    wrapper.fun = fun  # type: ignore[attr-defined]
    return wrapper


def _is_array(x) -> bool:
    import jax
    import numpy as np

    return isinstance(x, (jax.Array, np.ndarray, np.generic))


def _fast_key(treedef, static: list, specs: list):
    """The in-memory key of a call (None when a static leaf is not hashable)."""
    import jax

    key = ("fast", treedef, tuple(static), tuple((s.shape, str(s.dtype), s.weak_type) for s in specs),
           jax.default_backend(), jax.config.jax_enable_x64, jax.config.jax_default_matmul_precision)
    try:
        hash(key)
    except TypeError:
        return None
    return key


#: An object's default repr names its address, which changes per process: such a key would
#: never be found again, so the function runs unsaved instead of filling the folder.
_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")


def _key_text(name: str, treedef, static: list, specs: list) -> str | None:
    """Everything a saved program depends on, as text; None when part of it has no stable text."""
    import jax
    import jaxlib

    from fourierjax import __version__

    parts = [
        f"format={FORMAT}", f"function={name}", f"fourierjax={__version__}",
        f"source={source_hash()}", f"jax={jax.__version__}", f"jaxlib={jaxlib.__version__}",
        f"backend={jax.default_backend()}", f"x64={jax.config.jax_enable_x64}",
        f"matmul_precision={jax.config.jax_default_matmul_precision}",
        f"tree={treedef!r}", f"static={static!r}",
        "inputs=" + ";".join(f"{s.dtype}{list(s.shape)}{'w' if s.weak_type else ''}" for s in specs),
    ]
    text = "\n".join(parts)
    return None if _ADDRESS.search(text) else text


@functools.cache
def source_hash() -> str:
    """A hash of the package's source files (``*.py`` and ``*.toml`` under `fourierjax`), so that
    an edited checkout never loads a program traced from other code.

    Returns:
        A hex digest (computed once per process).
    """
    return tree_hash(pathlib.Path(__file__).resolve().parent)


def tree_hash(root: pathlib.Path) -> str:
    """The hash `source_hash` takes of the ``*.py`` and ``*.toml`` files under ``root``: their
    paths relative to it and their bytes.

    Arguments:
        root: a folder.

    Returns:
        A hex digest.
    """
    h = hashlib.sha256()
    for path in sorted(p for ext in ("*.py", "*.toml") for p in root.rglob(ext)):
        h.update(str(path.relative_to(root)).encode())
        h.update(b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


def _path(name: str, key: str, suffix: str = ".jaxexp") -> pathlib.Path:
    from fourierjax import _compile_cache

    digest = hashlib.sha256(key.encode()).hexdigest()[:40]
    short = re.sub(r"[^A-Za-z0-9_.]", "_", name.rsplit(".", 1)[-1])[:40]
    return pathlib.Path(_compile_cache.saved_dir()) / f"{short}-{digest}{suffix}"


def _runner(exported, cpu_compiler_options: dict | None) -> Callable:
    """The exported program as a jitted call, compiled with the entry points' XLA options."""
    import jax

    from fourierjax import _jit

    opts = {}
    if jax.default_backend() == "cpu":
        opts = {"compiler_options": _jit._cpu_options() if cpu_compiler_options is None
                else _jit._known_options(cpu_compiler_options)}
    return jax.jit(exported.call, **opts)


def _load(path: pathlib.Path, key: str, specs: list, cpu_compiler_options) -> tuple | None:
    """The saved program at ``path`` as ``(runner, output skeleton)``, or None (missing, or
    not usable: logged at debug level)."""
    try:
        blob = path.read_bytes()
    except OSError:
        return None
    try:
        import jax

        record = _unpack(blob, _MAGIC, key, checksum=False)
        exported = jax.export.deserialize(bytearray(record["exported"]))
        got = [(tuple(a.shape), a.dtype) for a in exported.in_avals]
        if got != [(tuple(s.shape), s.dtype) for s in specs]:
            raise ValueError(f"its inputs {got} differ")
        out_skeleton = record["out"]
        out_leaves = jax.tree.leaves(out_skeleton)
        if sorted(out_leaves) != list(range(len(exported.out_avals))):
            raise ValueError("its output structure does not match its program")
        return _runner(exported, cpu_compiler_options), out_skeleton
    except Exception as err:  # noqa: BLE001 (any failure to load means: trace again)
        _log.debug("fourierjax: ignoring the saved program %s: %s", path, err)
        return None


def _export(fun, treedef, static, dynamic, specs, path: pathlib.Path, key: str,
            cpu_compiler_options) -> tuple | None:
    """Export ``fun`` for these inputs, save it, and return ``(runner, output skeleton)``;
    None when it cannot be exported."""
    import jax

    out_tree = []

    def flat(*arrays):
        it = iter(arrays)
        leaves = [next(it) if d else s for s, d in zip(static, dynamic, strict=True)]
        args, kwargs = jax.tree.unflatten(treedef, leaves)
        out_leaves, tree = jax.tree.flatten(fun(*args, **kwargs))
        out_tree.append(tree)
        return out_leaves

    try:
        exported = jax.export.export(jax.jit(flat))(*specs)
    except Exception as err:  # noqa: BLE001 (e.g. host callbacks): run unsaved
        _log.debug("fourierjax: %s cannot be saved as a program: %s", path.name, err)
        return None
    out_skeleton = jax.tree.unflatten(out_tree[-1], list(range(out_tree[-1].num_leaves)))
    try:
        blob = bytes(exported.serialize())
        # This call runs what later calls will read (a deserialized program's outputs are not
        # weakly typed, for one), so that its results, and the keys of the programs they feed,
        # are those of every later call.
        exported = jax.export.deserialize(bytearray(blob))
        record = {"key": key, "out": out_skeleton, "exported": blob}
        _write_atomic(path, _pack(_MAGIC, record, checksum=False))
    except Exception as err:  # noqa: BLE001 (unpicklable output, full disk: still run it)
        _log.debug("fourierjax: could not save the program %s: %s", path, err)
    return _runner(exported, cpu_compiler_options), out_skeleton


def _pack(magic: bytes, record: dict, *, checksum: bool) -> bytes:
    """A saved file's bytes: ``magic``, then (``checksum``) the SHA-256 of the pickled
    ``record`` and a newline, then the pickle."""
    body = pickle.dumps(record, protocol=pickle.HIGHEST_PROTOCOL)
    return magic + (hashlib.sha256(body).hexdigest().encode() + b"\n" if checksum else b"") + body


def _unpack(blob: bytes, magic: bytes, key: str, *, checksum: bool) -> dict:
    """The record `_pack` wrote, for ``key``; ValueError when ``blob`` is another kind of file,
    its checksum differs (checked before anything is unpickled) or its key differs."""
    if not blob.startswith(magic):
        raise ValueError(f"not a {magic.decode().strip()} file")
    body = blob[len(magic):]
    if checksum:
        digest, _, body = body.partition(b"\n")
        if hashlib.sha256(body).hexdigest().encode() != digest:
            raise ValueError("its checksum differs (truncated or corrupt)")
    record = pickle.loads(body)
    if not isinstance(record, dict) or record.get("key") != key:
        raise ValueError("its key differs (another version, machine or input)")
    return record


def _write_atomic(path: pathlib.Path, data: bytes) -> None:
    from fourierjax.io.atomic import write_bytes_atomic

    path.parent.mkdir(parents=True, exist_ok=True)
    write_bytes_atomic(path, data)


# ---------------------------------------------------------------------- saved executables

#: Bumped when the layout of a saved executable changes: older files are then ignored.
EXECUTABLE_FORMAT = 1
_EXECUTABLE_MAGIC = b"fourierjax-saved-executable\n"


def saved_executable(jitted: Callable) -> Callable:
    """Wrap a `fourierjax._jit.jit` function so that a fresh process loads its compiled program
    from disk instead of tracing, lowering and reading it from the compile cache.

    For the parse + FK of a fresh process (issue 25): the persistent compile cache skips XLA's
    compile, not the trace and the lowering before it (FK of a bundled clip: trace 0.03 +
    lowering 0.10 + cache read 0.06 s on a quiet 2-core machine). A saved executable
    (`jax.experimental.serialize_executable`) is loaded with neither. Only on CPU, only at the
    top level (outside jit, vmap, grad), only with every argument leaf an array, and only when
    `_compile_cache.saved_programs_on()`; otherwise, and whenever anything about the file is
    wrong, the wrapper calls `jitted`.

    A file is keyed by everything the executable depends on (`_executable_key`): the
    function, the input tree (the topology included) and avals, the fourierjax source, the
    jax and jaxlib versions, the backend, its platform version and device kind, the host CPU's
    model and feature flags (an executable compiled for other instructions must never run), the
    XLA options and flags, x64. It is written atomically and carries a SHA-256 of its payload:
    a truncated, corrupt or foreign file, or one whose key differs, is ignored (debug log) and
    replaced, never loaded.

    Arguments:
        jitted: from `fourierjax._jit.jit` (it has `.lower`).

    Returns:
        The wrapped function (with ``.stats``: ``"loaded"``, ``"saved"``, ``"plain"`` and
        ``"rejected"`` counts of this process, and the attributes of `jitted`).
    """
    programs: dict = {}
    stats = {"loaded": 0, "saved": 0, "plain": 0, "rejected": 0}
    name = f"{getattr(jitted, '__module__', '?')}.{getattr(jitted, '__qualname__', repr(jitted))}"

    @functools.wraps(jitted)
    def wrapper(*args):
        from fourierjax import _compile_cache, _jit

        if not _compile_cache.saved_programs_on() or not _jit._trace_state_clean():
            return jitted(*args)
        import jax

        leaves, treedef = jax.tree.flatten(args)
        if jax.default_backend() != "cpu" or not all(_is_array(x) for x in leaves):
            stats["plain"] += 1
            return jitted(*args)
        fast = (treedef, tuple((x.shape, jax.dtypes.canonicalize_dtype(x.dtype),
                                bool(getattr(x, "weak_type", False))) for x in leaves))
        compiled = programs.get(fast)
        read_from = None  # the file a program just loaded came from: its first run is checked
        if compiled is None:
            key = _executable_key(name, treedef, fast[1])
            if key is None:
                compiled = programs[fast] = False
            else:
                compiled, read_from = _executable(jitted, name, args, key, stats)
                programs[fast] = compiled
        if compiled is False:  # could not be saved or loaded: the plain function
            return jitted(*args)
        try:
            out = compiled(*args)
            if read_from is not None:
                jax.block_until_ready(out)
            return out
        except (TypeError, ValueError) as err:  # inputs the executable refuses: never again
            _log.debug("fourierjax: %s runs unsaved: %s", name, err)
            programs[fast] = False
            return jitted(*args)
        except jax.errors.JaxRuntimeError as err:
            if read_from is None:
                raise
            # A file that loads but fails to run (one lacking a kernel, e.g. saved by an
            # earlier version from a compile-cache hit): deleted, compiled afresh and saved.
            _log.debug("fourierjax: the saved executable %s fails to run (%s); compiling again",
                       read_from, err)
            stats["rejected"] += 1
            read_from.unlink(missing_ok=True)
            compiled, _ = _executable(jitted, name, args, key, stats)
            programs[fast] = compiled
            return jitted(*args) if compiled is False else compiled(*args)

    wrapper.stats = stats  # type: ignore[attr-defined]
    return wrapper


def _executable(jitted, name: str, args: tuple, key: str, stats: dict):
    """The compiled program of ``jitted(*args)`` and the path it was read from: loaded from its
    file (the path), else compiled afresh and saved (None); False when it can be neither."""
    path = _path(name, key, ".xlaexe")
    compiled = _load_executable(path, key)
    if compiled is not None:
        stats["loaded"] += 1
        return compiled, path
    if path.exists():
        stats["rejected"] += 1
    try:
        with _compile_cache_bypassed():
            compiled = jitted.lower(*args).compile()
    except Exception as err:  # noqa: BLE001 (the plain call raises it again, or runs)
        _log.debug("fourierjax: %s cannot be compiled ahead: %s", name, err)
        return False, None
    try:
        from jax.experimental import serialize_executable

        payload, in_tree, out_tree = serialize_executable.serialize(compiled)
        record = {"key": key, "payload": bytes(payload), "in_tree": in_tree, "out_tree": out_tree}
        _write_atomic(path, _pack(_EXECUTABLE_MAGIC, record, checksum=True))
        stats["saved"] += 1
    except Exception as err:  # noqa: BLE001 (unserializable, full disk: still run it)
        _log.debug("fourierjax: could not save the executable %s: %s", path, err)
    return compiled, None


@contextlib.contextmanager
def _compile_cache_bypassed():
    """Compile without JAX's persistent compile cache (no read, no write) inside the block.

    jaxlib 0.10 serializes an XLA:CPU executable that was read from the persistent cache
    without some of its kernels: `fk_frames`' program serializes to 386,934 bytes against
    497,962 compiled afresh, and the next process that loads it fails at run time ("NOT_FOUND:
    Function gather.12_kernel not found"). So a program that is to be saved is compiled afresh.
    JAX has no public switch for this once the cache is in use (`jax_enable_compilation_cache`
    is read once per process), so the block sets the module's memo of it; a compile on another
    thread meanwhile also skips the cache (slower, never wrong). Where that memo is missing (a
    later jax), the block changes nothing, and `saved_executable`'s check of a loaded file's
    first run still catches a broken file.
    """
    try:
        from jax._src import compilation_cache as cc

        cc._cache_checked, cc._cache_used  # noqa: B018 (present in this jax?)
    except (ImportError, AttributeError):
        yield
        return
    # Nested or on two threads at once: the memo is set by the first block in and put back by
    # the last out, never restored to another block's "off".
    with _BYPASS_LOCK:
        if _BYPASS["depth"] == 0:
            _BYPASS["before"] = (cc._cache_checked, cc._cache_used)
            cc._cache_checked, cc._cache_used = True, False
        _BYPASS["depth"] += 1
    try:
        yield
    finally:
        with _BYPASS_LOCK:
            _BYPASS["depth"] -= 1
            if _BYPASS["depth"] == 0:
                cc._cache_checked, cc._cache_used = _BYPASS["before"]


_BYPASS_LOCK = threading.Lock()
_BYPASS: dict = {"depth": 0, "before": None}


def _load_executable(path: pathlib.Path, key: str):
    """The executable saved at ``path`` for ``key``, or None (missing or not usable: logged at
    debug level). The checksum and key are checked before anything is unpickled or loaded."""
    try:
        blob = path.read_bytes()
    except OSError:
        return None
    try:
        record = _unpack(blob, _EXECUTABLE_MAGIC, key, checksum=True)
        from jax.experimental import serialize_executable

        return serialize_executable.deserialize_and_load(record["payload"], record["in_tree"],
                                                         record["out_tree"])
    except Exception as err:  # noqa: BLE001 (any failure to load means: compile again)
        _log.debug("fourierjax: ignoring the saved executable %s: %s", path, err)
        return None


def _executable_key(name: str, treedef, avals: tuple) -> str | None:
    """Everything a saved executable depends on, as text (see `saved_executable`); None when
    part of it has no stable text (an address in a repr)."""
    import os

    import jax
    import jaxlib

    from fourierjax import __version__, _jit

    device = jax.devices()[0]
    parts = [
        f"format={EXECUTABLE_FORMAT}", f"function={name}", f"fourierjax={__version__}",
        f"source={source_hash()}", f"jax={jax.__version__}", f"jaxlib={jaxlib.__version__}",
        f"backend={jax.default_backend()}", f"platform={device.platform}",
        f"platform_version={getattr(device.client, 'platform_version', '?')}",
        f"device_kind={device.device_kind}", f"cpu={host_cpu()}",
        f"options={sorted(_jit._cpu_options().items())}", f"xla_flags={os.environ.get('XLA_FLAGS', '')}",
        f"x64={jax.config.jax_enable_x64}", f"matmul_precision={jax.config.jax_default_matmul_precision}",
        f"tree={treedef!r}", "inputs=" + ";".join(f"{d}{list(s)}{'w' if w else ''}" for s, d, w in avals),
    ]
    text = "\n".join(parts)
    return None if _ADDRESS.search(text) else text


@functools.cache
def host_cpu() -> str:
    """The host CPU's model and feature flags (Linux: ``/proc/cpuinfo``; elsewhere the
    processor's name), hashed: an executable compiled for one CPU may use instructions another
    lacks.

    Returns:
        A hex digest.
    """
    import platform

    text = f"{platform.machine()} {platform.processor()}"
    try:
        with open("/proc/cpuinfo") as f:
            lines = [ln for ln in f if ln.split(":")[0].strip() in ("model name", "flags", "Features")]
        text += "".join(sorted(set(lines)))
    except OSError:
        pass
    return hashlib.sha256(text.encode()).hexdigest()
