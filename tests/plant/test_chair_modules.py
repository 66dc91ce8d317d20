"""``wcdrive.plant.chair`` keeps every name it had, now that its concerns live in modules
of their own: the kernel's binding (``chair_kernel``), the force model
(``force_model``), the walls and collisions (``contacts``) and the motion log
(``motion_log``). Each name is the very object of the module that holds it."""

from __future__ import annotations

import pytest

from wcdrive.plant import chair, chair_kernel, contacts, force_model

#: The public names of ``wcdrive.plant.chair`` and the module that holds each.
NAMES = {
    "Plant": chair, "WheelView": chair,
    "ChairStruct": chair_kernel, "load_kernel": chair_kernel, "KernelSampler": chair_kernel,
    "SWIVEL_RATE_SCALE": force_model, "SCRUB_SLIP": force_model, "BRAKE_SLACK": force_model,
    "CONTACT_SLOP": contacts, "CONTACT_BIAS": contacts, "WALL_FRICTION": contacts,
    "IMPACT_WINDOW": contacts, "KEEP_FIRST": contacts, "KEEP_LARGEST": contacts,
    "Contact": contacts, "Contacts": contacts, "footprint": contacts,
}


@pytest.mark.parametrize("name", sorted(NAMES))
def test_each_name_is_importable_from_chair(name: str) -> None:
    assert getattr(chair, name) is getattr(NAMES[name], name)


def test_chair_exports_exactly_these() -> None:
    assert sorted(chair.__all__) == sorted(NAMES)
