"""The compiled kernels' cache key (model.kernels.kernel_key): what defines a kernel, without serialising it.

A key that misses a change would load a stale library (wrong numbers with no warning); a key that changes
between two builds of the same kernel would recompile in every process. The kernels are per element kind,
not per structure: every structure with beams uses the one beam kernel, so "the same kernel" here is one
factory of model/elements.py built twice, and "different kernels" are the factories' distinct outputs.
"""

from __future__ import annotations

import ast
from pathlib import Path

import casadi as ca
import flexopt.model.elements as E
import numpy as np
import pytest
from flexopt.model import kernels as K

MODEL = Path(K.__file__).parent

#: Every KernelSpec factory of model/elements.py with its arguments.
FACTORIES = (
    (E.beam_spec, ()),
    (E.truss_spec, ()),
    (E.joint_spec, ()),
    (E.beam_mass_spec, ()),
    (E.beam_mass_jvp_spec, ()),
    (E.beam_jvp_spec, ()),
    (E.beam_jvp_gradient_spec, ()),
    (E.rotation_update_spec, ()),
    (E.rotation_log_spec, ()),
    (E.von_mises_spec, ()),
    (E.point_load_spec, ()),
    (E.beam_gravity_spec, ()),
    (E.load_jvp_spec, ("point",)),
    (E.load_jvp_spec, ("beam_gravity",)),
)


def _specs(build, args: tuple) -> list[E.KernelSpec]:
    out = build(*args)
    return list(out) if isinstance(out, tuple) else [out]


def _key(spec: E.KernelSpec) -> tuple[str, ...]:
    return K.kernel_key(spec, K.native_source("kernel_batch.c", K.batch_definitions(spec)))


def test_every_kernel_has_its_own_key_and_a_rebuild_the_same() -> None:
    """Each factory's kernels (main and third derivative) get distinct keys; building a factory again from its
    code (``__wrapped__``: past functools.cache, new CasADi symbols; the two jvp kernels reuse their cached function) gives the same key."""
    public = {
        f
        for n, f in vars(E).items()
        if not n.startswith("_") and "KernelSpec" in getattr(f, "__annotations__", {}).get("return", "")
    }
    assert public == {f for f, _ in FACTORIES}  # every factory is checked here
    keys = {}
    for factory, args in FACTORIES:
        for spec, again in zip(_specs(factory, args), _specs(factory.__wrapped__, args)):
            assert _key(again) == _key(spec), spec.name
            keys[spec.name] = _key(spec)
    assert len(set(keys.values())) == len(keys) == 17


def test_a_different_function_under_the_same_name_changes_the_key() -> None:
    """The key sees the function, not only its name: the truss kernel relabelled as the beam's does not get the
    beam's key (its sizes and instruction count differ, and so do the wrapper's work sizes)."""
    beam = E.beam_spec()[0]
    truss = E.truss_spec()[0]
    fake = E.KernelSpec(beam.name, truss.function, truss.n_in, truss.n_out, 1, E.TRUSS_STATE, E.TRUSS_CONST)
    assert _key(fake) != _key(beam)


def test_a_change_in_the_generating_code_changes_the_key(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """One comment line added to a copy of model/elements.py changes every kernel's key."""
    spec = E.beam_spec()[1]
    before = _key(spec)
    edited = tmp_path / "elements.py"
    edited.write_text(K.GENERATORS[0].read_text() + "# edited\n")
    monkeypatch.setattr(K, "GENERATORS", (edited,))
    K.generator_hash.cache_clear()
    try:
        assert _key(spec) != before
    finally:
        monkeypatch.undo()
        K.generator_hash.cache_clear()
    assert _key(spec) == before


def test_only_the_generators_build_kernels() -> None:
    """The key hashes :data:`model.kernels.GENERATORS` in place of the function, which is safe only if the
    functions come from those files alone: no other file of the package constructs a KernelSpec, the
    generators import no flexopt module at their top, and no function that builds a KernelSpec reaches
    (through the file's own functions) one that imports a flexopt module."""
    names = {f.name for f in K.GENERATORS}
    package = [p for d in ("model", "optim", "service") for p in (MODEL.parent / d).rglob("*.py")]
    builders = {p.relative_to(MODEL.parent).as_posix() for p in package if "KernelSpec(" in p.read_text()}
    assert builders == {f"model/{n}" for n in names}
    for path in K.GENERATORS:
        tree = ast.parse(path.read_text())
        assert not [n for n in tree.body if isinstance(n, ast.ImportFrom) and n.level > 0], path.name
        funcs = {n.name: n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)}
        calls = {
            name: {c.id for c in ast.walk(f) if isinstance(c, ast.Name) and c.id in funcs} for name, f in funcs.items()
        }
        importing = {
            name
            for name, f in funcs.items()
            if any(isinstance(n, ast.ImportFrom) and n.level > 0 or isinstance(n, ast.Import) for n in ast.walk(f))
        }
        reached = {
            name
            for name, f in funcs.items()
            if any(isinstance(c, ast.Name) and c.id == "KernelSpec" for c in ast.walk(f))
        }
        todo = list(reached)
        while todo:
            for callee in calls[todo.pop()] - reached:
                reached.add(callee)
                todo.append(callee)
        assert len(reached) > 10  # the walk found the builders
        assert not reached & importing, (path.name, sorted(reached & importing))


def test_a_cached_kernel_loads_without_serialising(monkeypatch: pytest.MonkeyPatch) -> None:
    """A kernel already in the disk cache is loaded, and evaluates as CasADi does, with ``casadi.Function.serialize`` broken:
    the key no longer costs a serialisation (0.1-0.3 s for the beam's third-derivative kernel)."""
    if K._compiler() is None:
        pytest.skip("no C compiler: kernels run in CasADi's virtual machine, no cache")
    spec = E.rotation_update_spec()
    K.compiled(spec)  # in the disk cache from here on

    def refuse(self: ca.Function, *args: object) -> str:
        raise AssertionError("serialised")

    monkeypatch.setattr(ca.Function, "serialize", refuse)
    kernel = K.CompiledKernel(spec)
    assert kernel.address is not None
    x = np.random.default_rng(0).standard_normal((3, spec.n_in))
    vm = np.asarray(spec.function.map(3)(x.T)).T  # CasADi's virtual machine, the same function uncompiled
    assert np.allclose(kernel(x), vm, rtol=1e-12, atol=1e-12)  # C and the VM: same operations, rounding apart
