"""User effects loaded with ``--effect`` (issue 11, item 7): a plug-in runs its module's
code, may come as a ``.py`` path, and must not shadow a library effect."""

from __future__ import annotations

import pytest

from rotor_env.diagnosis import load_user_effect
from rotor_env.effects import EFFECTS

# user effects registered here must not leak into other tests (conftest.py)
pytestmark = pytest.mark.usefixtures("restore_effect_registry")


def test_plugin_shadowing_a_library_effect_is_refused(tmp_path):
    path = tmp_path / "shadow.py"
    path.write_text(
        "def asymmetry(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):\n"
        "    return (-th_y,), (-th_x,)\n"
    )
    library = EFFECTS["asymmetry"]
    with pytest.raises(ValueError, match=r"'asymmetry' is a library effect; give the plug-in another name"):
        load_user_effect(f"{path}:asymmetry")
    assert EFFECTS["asymmetry"] is library  # untouched


def test_plugin_from_a_py_path_loads_and_reloads(tmp_path):
    path = tmp_path / "mine.py"
    path.write_text(
        "def cubic(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):\n"
        "    r2 = th_x * th_x + th_y * th_y\n"
        "    return (-th_y * r2,), (-th_x * r2,)\n"
    )
    first = load_user_effect(f"{path}:cubic")
    assert EFFECTS["cubic"] is first
    second = load_user_effect(f"{path}:cubic")  # the same plug-in twice: replaced, no error
    assert EFFECTS["cubic"] is second
