"""The calibrated URDF: the identified inertial parameters, armature and transmission written into
the URDF's text."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from fricli.core.errors import ModelFileError
from fricli.robot.calibration.parameters import _pin
from fricli.robot.calibration.report import whole_bodies
from fricli.robot.calibration.result import Calibration


def calibrated_urdf(urdf_text: str, name: str, cal: Calibration) -> str:
    """``urdf_text`` with the identified inertial parameters of every moving link (its own inertia
    plus the identified change of its body: links fixed to it keep theirs, unless ``whole_bodies``
    says the moving link takes all of the body) and the armature as
    Pinocchio's ``<rotor_params>`` (gear_ratio 1, mass = armature); with a transmission also each
    motor's rotor inertia and row of R as ``<fricli_transmission>`` (``fricli.robot.dynamics``)."""
    from fricli.robot.dynamics import TRANSMISSION, link_inertials

    pin = _pin()
    own_links = link_inertials(urdf_text, name)
    root = ET.fromstring(urdf_text, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    links = {link.get("name"): link for link in root.findall("link")}
    nj = len(cal.joints)
    for b, (body, whole) in enumerate(zip(cal.bodies, whole_bodies(cal))):
        link = links.get(body)
        if link is None:
            raise ModelFileError(f"{name}: no link {body!r} for joint {cal.joints[b]}")
        if whole:
            _set_inertial(link, pin.Inertia.FromDynamicParameters(cal.links()[10 * b:10 * b + 10]))
            for other in cal.attached[b]:
                for inertial in links[other].findall("inertial"):
                    links[other].remove(inertial)
        else:
            delta = cal.x[10 * b:10 * b + 10] - cal.x0[10 * b:10 * b + 10]
            _set_inertial(link, pin.Inertia.FromDynamicParameters(own_links[body] + delta))
    for old in root.findall("rotor_params") + root.findall(TRANSMISSION):
        root.remove(old)
    if len(root):
        root[-1].tail = "\n  "
    rotor = ET.SubElement(root, "rotor_params")
    rotor.text, rotor.tail = "\n    ", "\n"
    for j, (joint, a) in enumerate(zip(cal.joints, cal.armature())):
        element = ET.SubElement(rotor, "joint", {"name": joint, "mass": repr(float(a)), "gear_ratio": "1"})
        element.tail = "\n    " if j < nj - 1 else "\n  "
    if cal.motors is not None:
        rotor.tail = "\n  "
        listed = ET.SubElement(root, TRANSMISSION)
        listed.text, listed.tail = "\n    ", "\n"
        for k, m in enumerate(cal.motors):
            motor = ET.SubElement(listed, "motor", {"joint": cal.joints[m], "rotor_inertia": repr(float(cal.x[10 * nj + m]))})
            for j in cal.motors:
                if cal.ratio[m, j]:
                    ET.SubElement(motor, "ratio", {"joint": cal.joints[j], "value": repr(float(cal.ratio[m, j]))})
            motor.tail = "\n    " if k < len(cal.motors) - 1 else "\n  "
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _set_inertial(link, inertia) -> None:
    """Write ``inertia`` (a pin.Inertia in the link frame) as the link's <inertial>, rpy = 0."""
    inertial = link.find("inertial")
    if inertial is None:
        inertial = ET.SubElement(link, "inertial")
    for child in list(inertial):
        inertial.remove(child)
    c, tensor = inertia.lever, inertia.inertia
    w, v = np.linalg.eigh(tensor)
    if w.min() < 0:            # a body the fit shrank to a point: the round-off of its moments is no inertia
        tensor = (v * np.maximum(w, 0.0)) @ v.T
    inertial.text = "\n      "
    ET.SubElement(inertial, "mass", {"value": repr(float(inertia.mass))}).tail = "\n      "
    ET.SubElement(inertial, "origin", {"xyz": " ".join(repr(float(v)) for v in c), "rpy": "0 0 0"}).tail = "\n      "
    ET.SubElement(inertial, "inertia", {k: repr(float(tensor[a, b])) for k, (a, b) in (
        ("ixx", (0, 0)), ("ixy", (0, 1)), ("ixz", (0, 2)), ("iyy", (1, 1)), ("iyz", (1, 2)), ("izz", (2, 2)))}).tail = "\n    "


def report_path(output: str) -> str:
    """The report written beside OUT.urdf: OUT.calibration.json."""
    stem = output[:-5] if output.lower().endswith(".urdf") else output
    return stem + ".calibration.json"


def write(text: str, report: dict, output: str, report_file: str | None = None) -> str | None:
    """Write the calibrated URDF ``text`` to ``output`` ("-": stdout) and ``report`` (with
    its own path as "report") to ``report_file`` (default ``report_path(output)``; none for "-");
    the report's path."""
    from fricli.core import jsontext
    from fricli.core.atomic import atomic_write_bytes

    import os

    from fricli.core.errors import OutputError

    where = report_file or (None if output == "-" else report_path(output))
    for path in (output, where):   # both folders first: a failed report must not leave a new URDF
        folder = os.path.dirname(os.path.abspath(path)) if path not in (None, "-") else None
        if folder is not None and not os.path.isdir(folder):
            raise OutputError(f"cannot write {path}: folder {folder} does not exist")
    report["report"] = where
    atomic_write_bytes(output, text.encode())
    if where:
        atomic_write_bytes(where, jsontext.dumps(report).encode())
    return where
