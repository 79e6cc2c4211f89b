"""``--model auto``: the cheapest level of the fidelity ladder that the scene needs.

Start from the kinematic level; escalate only when the kinetostatic MR13D changes sign over the
rise (the follower can leave the flank) and the groove has backlash.
"""
from __future__ import annotations

from models.scene import Scene


def choose_level(scene: Scene, needs_contact_outputs: bool = False) -> tuple[str, str]:
    """(level, reason). ``needs_contact_outputs``: the caller asks for x_el or contact forces."""
    if needs_contact_outputs:
        return "elastic", "contact outputs (x_el, contact force) were requested"
    from models.simulate import _kinematic
    kin = _kinematic(scene)
    mx, mn = kin.indicators["MR13D_max_Nm"], kin.indicators["MR13D_min_Nm"]
    if not (mx > 0 > mn):
        return "kinematic", (f"MR13D keeps its sign over the rise ({mn:.3g} to {mx:.3g} N m): "
                             "no contact loss, the kinematic level is exact for this scene")
    if scene.backlash == 0.0 and scene.omega1_mode == "const":
        return "kinematic", "MR13D changes sign but the groove has no backlash and omega1 is constant"
    return "rigid", (f"MR13D changes sign over the rise ({mn:.3g} to {mx:.3g} N m) with backlash "
                     f"{scene.backlash * 1e3:g} mm: jumps and impacts need the rigid model with backlash")
