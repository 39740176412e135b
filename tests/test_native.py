"""The C sources of the compiled routes (model/native/*.c, package data): each compiles without a warning under
``-Wall -Wextra -Werror`` with what its builder defines in front of it, and the slot tables C indexes by name are
generated from their one Python list (model.kernels.c_enum)."""

from __future__ import annotations

import subprocess

import pytest
from flexopt.model import assembly, kernels, linalg, statics
from flexopt.model.elements import rotation_update_spec

CC = kernels._compiler()
needs_cc = pytest.mark.skipif(CC is None, reason="no C compiler (gcc, cc or $CC) to compile model/native with")


def _variants() -> dict[str, list[tuple[str, tuple, str]]]:
    """Every native source with each set of definitions its builder puts in front of it: (label, defines,
    prelude). The kernel wrapper is compiled alone (its CasADi function declared, not defined)."""
    return {
        "assemble.c": [("", *assembly.assemble_source_definitions())],
        "kernel_batch.c": [("rot_update", kernels.batch_definitions(rotation_update_spec()), "")],
        "linalg.c": [(t, *linalg.source_definitions(t)) for t in ("long long", "int")],
        "newton_point.c": [("", *statics.loop_source_definitions())],
    }


def test_every_native_source_has_its_definitions_here() -> None:
    """A new file in model/native is compiled by the test below only once it is listed in _variants."""
    assert sorted(_variants()) == kernels.native_files()


@needs_cc
@pytest.mark.parametrize(
    "file,label,defines,prelude",
    [(f, *v) for f, vs in _variants().items() for v in vs],
    ids=lambda x: x if isinstance(x, str) else None,
)
def test_native_source_compiles_without_warnings(tmp_path, file: str, label: str, defines: tuple, prelude: str) -> None:
    """gcc (or $CC) with the builds' own flags (model.kernels.FLAGS: ``-Wall -Wextra``) and ``-Werror``, to an
    object file: a warning fails the test with the compiler's message."""
    src = tmp_path / file
    src.write_text(kernels.native_source(file, defines, prelude))
    flags = [f for f in kernels.FLAGS if f != "-shared"]
    proc = subprocess.run(
        [CC, *flags, "-Werror", "-c", str(src), "-o", str(tmp_path / "out.o")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr


def test_flags_ask_for_warnings() -> None:
    assert {"-Wall", "-Wextra"} <= set(kernels.FLAGS)


@pytest.mark.parametrize("slots", [statics.LOOP_SLOTS, assembly.MASS_SLOTS], ids=["loop", "mass"])
def test_c_enum_numbers_the_python_list_in_order(slots: tuple) -> None:
    """The enums C indexes the Newton loop's and the mass's contexts with: slot i of model.statics.LOOP_SLOTS
    (model.assembly.MASS_SLOTS) is enumerator i; names equal up to case, or not C identifiers, are refused (they
    would collide or not compile)."""
    text = kernels.c_enum(slots, "slot")
    body = text[text.index("{") + 1 : text.index("}")]
    assert [x.strip() for x in body.split(",")] == [s.upper() for s in slots]
    with pytest.raises(ValueError):
        kernels.c_enum(["n", "N"], "bad")
    with pytest.raises(ValueError):
        kernels.c_enum(["x-work"], "bad")


@needs_cc
@pytest.mark.parametrize("slots", [statics.LOOP_SLOTS, assembly.MASS_SLOTS], ids=["loop", "mass"])
def test_enum_values_seen_by_c_match_the_python_positions(tmp_path, slots: tuple) -> None:
    """Compiled and run: the value of every slot's enumerator in C is the slot's position in the Python list (what
    the compiled Newton loop's and mass's context arrays are built by)."""
    prelude = kernels.c_enum(slots, "slot")
    prints = "".join(f'  printf("%d\\n", (int) {s.upper()});\n' for s in slots)
    src = tmp_path / "slots.c"
    src.write_text(prelude + "#include <stdio.h>\nint main(void) {\n" + prints + "  return 0;\n}\n")
    exe = tmp_path / "slots"
    subprocess.run([CC, str(src), "-o", str(exe)], check=True, capture_output=True)
    out = subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout.split()
    assert [int(x) for x in out] == list(range(len(slots)))


def test_native_off_switches_every_compiled_part_off(monkeypatch) -> None:
    """System.native.off(), which the bit-for-bit comparisons of tests/test_linalg.py use to get the numpy routes:
    inside it no NativeRoute call runs (evaluate, mass, update, Hessian derivative) and the Newton system and loop
    are not offered; outside it they run again. Checked by counting the calls, so an off() that switched nothing
    off fails here (the comparisons themselves would then compare the C route with itself and pass)."""
    import numpy as np
    from flexopt.model import Analysis, template
    from flexopt.model.assembly import NativeRoute
    from flexopt.model.statics import _point_loop

    an = Analysis(template("cross-spring-pivot"))
    sys_ = an.system
    if sys_.native.assemble_call is None:
        pytest.skip("no compiled route here (no C compiler)")
    calls: list[str] = []
    for name in ("evaluate", "mass", "update", "hessian_derivative", "call"):
        orig = getattr(NativeRoute, name)
        monkeypatch.setattr(
            NativeRoute, name, lambda self, *a, _orig=orig, _name=name: calls.append(_name) or _orig(self, *a)
        )
    st = sys_.reference_state()
    step = np.full(sys_.n, 1e-3)

    def run() -> None:
        sys_.evaluate(st), sys_.mass(st), sys_.update(st, step), sys_.hessian_derivative(st, step)

    run()
    assert {"evaluate", "mass", "update", "hessian_derivative"} <= set(calls)
    assert _point_loop(sys_, an.options) is not None and sys_.native.newton_system() is not None
    calls.clear()
    with sys_.native.off():
        run()
        assert _point_loop(sys_, an.options) is None and sys_.native.newton_system() is None
        assert sys_.native.point_parts() is None and sys_.native.mass_context() is None
    assert calls == []
    run()
    assert {"evaluate", "mass", "update", "hessian_derivative"} <= set(calls)
    assert _point_loop(sys_, an.options) is not None


def test_no_c_source_in_python_strings() -> None:
    """The C of the compiled routes lives in model/native/*.c, not in Python strings (issue 27: 877 lines of C were in
    string constants of model/linalg.py, statics.py, assembly.py and kernels.py): no string constant in the model
    package holds a C ``#include``."""
    import ast
    from pathlib import Path

    import flexopt.model as model

    found = []
    for path in Path(model.__file__).parent.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and "#include" in node.value:
                found.append(f"{path.name}:{node.lineno}")
    assert found == []
