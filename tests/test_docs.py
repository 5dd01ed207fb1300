"""The documentation follows the code: the effect catalogue is generated, PHYSICS.md is local."""

from __future__ import annotations

from pathlib import Path

import pytest

import rotor_env
from rotor_env.effects import EFFECTS, PHYSICAL_EFFECTS
from rotor_env.effects_doc import effects_markdown, main

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
REGENERATE = "run `python -m rotor_env.effects_doc` to regenerate docs/EFFECTS.md"


def _catalogue() -> str:
    path = DOCS / "EFFECTS.md"
    assert path.is_file(), f"docs/EFFECTS.md is missing: {REGENERATE}"
    return path.read_text(encoding="utf-8")


def _package_effects():
    # the registry as the package leaves it; effects other tests register are not listed
    assert set(rotor_env.PACKAGE_EFFECTS) <= set(EFFECTS)
    return {name: EFFECTS[name] for name in rotor_env.PACKAGE_EFFECTS}


def test_catalogue_is_generated_from_the_declarations():
    assert _catalogue() == effects_markdown(), f"docs/EFFECTS.md is out of date: {REGENERATE}"


def test_catalogue_lists_every_effect_and_parameter():
    text = _catalogue()
    sections = text.split("\n## ")
    for name, eff in _package_effects().items():
        matching = [s for s in sections if s.startswith(f"`{name}`\n")]
        assert len(matching) == 1, f"no section for effect {name!r} in docs/EFFECTS.md: {REGENERATE}"
        for p in eff.parameters:
            assert f"`{p.name}`" in matching[0], (
                f"parameter {p.name!r} of {name!r} missing from docs/EFFECTS.md: {REGENERATE}"
            )


def test_catalogue_lists_only_the_package_effects():
    from rotor_env.effects import Effect, Parameter

    extra = Effect(
        name="_doc_test_effect",
        parameters=(Parameter("_doc_test_p", 0.0, "a test parameter"),),
        coefficients=("_doc_test_p",),
        columns=lambda *a: ((a[3],), (a[4],)),
        to_coefficients=lambda p: (p["_doc_test_p"],),
        from_coefficients=lambda c: {"_doc_test_p": float(c[0])},
        moment="none", cause="a test", signature="none",
    )
    EFFECTS[extra.name] = extra
    try:
        assert "_doc_test_effect" not in effects_markdown()
        assert "## `_doc_test_effect`" in effects_markdown({extra.name: extra})
    finally:
        del EFFECTS[extra.name]


def test_main_writes_the_catalogue(tmp_path, capsys):
    out = tmp_path / "EFFECTS.md"
    assert main([str(out)]) == 0
    assert out.read_text(encoding="utf-8") == effects_markdown()
    assert main([str(out)]) == 0  # replaces its own output
    assert str(out) in capsys.readouterr().out


def test_physics_mentions_every_effect_of_the_paper():
    text = (DOCS / "PHYSICS.md").read_text(encoding="utf-8")
    for name in PHYSICAL_EFFECTS:
        assert f"`{name}`" in text, f"docs/PHYSICS.md does not mention effect {name!r}"


@pytest.mark.parametrize("where", ["rotor_env", "identifier", "agents", "README.md"])
def test_no_reference_to_the_shared_physics_file(where):
    base = ROOT / where
    files = [base] if base.is_file() else [
        p for p in base.rglob("*")
        if p.is_file() and "__pycache__" not in p.parts and p.suffix in {".py", ".md", ".txt", ".yml", ".yaml", ".rst"}
    ]
    offenders = [
        f"{p.relative_to(ROOT)}:{i}"
        for p in files
        for i, line in enumerate(p.read_text(encoding="utf-8", errors="replace").splitlines(), 1)
        if "shared/PHYSICS.md" in line
    ]
    assert not offenders, f"refer to docs/PHYSICS.md instead of the shared file: {offenders}"
