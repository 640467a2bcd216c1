"""
A payload the URDF does not carry (a tool, a grasped part), added to the URDF as a link.

Real arms are told their payload (a UR controller's payload mass and centre of gravity, a
Franka's load): the links of the URDF are not all the arm carries, and gravity compensation
with the links alone leaves the weight of the rest to the potential, which then holds the tip
where its stiffness balances that weight, short of the goal. A :class:`Payload` is one,
validated. :func:`with_payload` returns the URDF with it as one more link, fixed to the link
that carries it: what the simulator's plant (PyBullet, MuJoCo) loads. The controller's model
adds the same inertia to the body of the tip's joint in place (``RobotModel.set_payload``), so
that it can change while the controller runs (a part grasped, a tool changed); the tests check
the two ways against each other.

The payload is a point mass, within the 1 cm sphere the URDF needs for an inertia
(``PAYLOAD_RADIUS_M``): its weight and its lever are what matter to g(q), and a tool whose own
inertia matters belongs in the URDF as links.
"""
from dataclasses import dataclass
from math import isfinite
from typing import Mapping, Sequence
from xml.etree import ElementTree

PAYLOAD_RADIUS_M = 0.01  # the sphere whose inertia the payload link is given
PAYLOAD_MASS_MAX_KG = 1000.0  # the parameters' range (the arm's own limits come first)
PAYLOAD_LINK_SUFFIX = '_payload'


def payload_values(mass_kg: float, com_m: Sequence[float]) -> tuple[float, tuple[float, ...]]:
    """
    Return ``(mass_kg, com_m)`` checked: a finite mass >= 0 and three finite coordinates.

    Raises ValueError naming the bad value (``payload_mass``, ``payload_com``: the parameters'
    names).
    """
    try:
        mass = float(mass_kg)
    except (TypeError, ValueError):
        raise ValueError(f'payload_mass must be a number (kg), got {mass_kg!r}') from None
    if not isfinite(mass) or mass < 0.0:
        raise ValueError(f'payload_mass must be finite and >= 0 kg, got {mass}')
    try:
        com = tuple(float(c) for c in com_m)
    except (TypeError, ValueError):
        raise ValueError(f'payload_com must be 3 numbers (m), got {com_m!r}') from None
    if len(com) != 3 or not all(isfinite(c) for c in com):
        raise ValueError('payload_com must be 3 finite numbers, x y z in m in the frame of '
                         f'the link that carries it, got {list(com)}')
    return mass, com


@dataclass(frozen=True)
class Payload:
    """A payload, validated: ``mass_kg`` >= 0 at ``com_m`` (m, in the carrying link's frame)."""

    mass_kg: float = 0.0
    com_m: tuple[float, ...] = (0.0, 0.0, 0.0)

    @classmethod
    def create(cls, mass_kg: float, com_m: Sequence[float]) -> 'Payload':
        """Return the payload checked (:func:`payload_values`); ValueError names a bad value."""
        return cls(*payload_values(mass_kg, com_m))

    @classmethod
    def from_parameters(cls, values: Mapping) -> 'Payload':
        """Return the payload of ``payload_mass`` and ``payload_com`` (absent: 0, the origin)."""
        return cls.create(values.get('payload_mass', 0.0),
                          values.get('payload_com', (0.0, 0.0, 0.0)))

    def describe(self, link: str) -> str:
        """Return the payload in words, for the log."""
        return (f'payload {self.mass_kg:g} kg at {list(self.com_m)} m in {link}'
                if self.mass_kg > 0.0 else 'no payload')


def with_payload(urdf_xml: str, link: str, mass_kg: float, com_m: Sequence[float]) -> str:
    """
    Return the URDF with a payload of ``mass_kg`` at ``com_m`` (m, in ``link``'s frame).

    The payload is a link named ``<link>_payload`` (with underscores added until the name is
    free) on a fixed joint of the same name plus ``_joint``. A mass of 0 returns the text as it
    is. Raises ValueError naming a bad value, a text that is not XML, or a link that is not in
    the URDF.
    """
    mass, com = payload_values(mass_kg, com_m)
    if mass == 0.0:
        return urdf_xml
    try:
        root = ElementTree.fromstring(urdf_xml)
    except ElementTree.ParseError as exc:
        raise ValueError(f'the URDF is not XML: {exc}') from None
    links = {e.get('name') for e in root.iter('link')}
    if link not in links:
        raise ValueError(f'link {link!r} is not in the URDF: no link carries the payload')
    taken = links | {e.get('name') for e in root.iter('joint')}
    name = link + PAYLOAD_LINK_SUFFIX
    while name in taken or name + '_joint' in taken:
        name += '_'
    inertia = 0.4 * mass * PAYLOAD_RADIUS_M ** 2  # a solid sphere's
    body = ElementTree.SubElement(root, 'link', name=name)
    inertial = ElementTree.SubElement(body, 'inertial')
    ElementTree.SubElement(inertial, 'origin', xyz='0 0 0', rpy='0 0 0')
    ElementTree.SubElement(inertial, 'mass', value=repr(mass))
    ElementTree.SubElement(inertial, 'inertia', ixx=repr(inertia), iyy=repr(inertia),
                           izz=repr(inertia), ixy='0', ixz='0', iyz='0')
    joint = ElementTree.SubElement(root, 'joint', name=name + '_joint', type='fixed')
    ElementTree.SubElement(joint, 'parent', link=link)
    ElementTree.SubElement(joint, 'child', link=name)
    ElementTree.SubElement(joint, 'origin', xyz=' '.join(repr(c) for c in com), rpy='0 0 0')
    return ElementTree.tostring(root, encoding='unicode')
