"""Generated serial chains for scaling benchmarks (any number of revolute joints)."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from .robot import Robot, load_robot


def _axes(dof: int) -> list[str]:
    """Joint axes of a generic chain: fixed pseudo-random unit vectors (no two parallel
    by construction of the seed), so no sub-chain is structurally singular."""
    rng = np.random.default_rng(7)
    axes = rng.normal(size=(dof, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    return [" ".join(f"{x:.6f}" for x in axis) for axis in axes]


def chain_urdf(dof: int, link_length: float = 0.12) -> str:
    """URDF text of a serial chain: ``dof`` revolute joints about generic fixed axes, each
    link ``link_length`` m along its own z (with a small sideways offset), then ``tool0``."""
    if dof < 1:
        raise ValueError(f"dof must be >= 1, got {dof}")
    parts = ['<?xml version="1.0"?>', f'<robot name="chain{dof}">', '  <link name="base_link"/>']
    parent = "base_link"
    axes = _axes(dof)
    for i in range(1, dof + 1):
        origin_z = 0.0 if i == 1 else link_length
        parts += [
            f'  <joint name="joint_{i}" type="revolute">',
            f'    <parent link="{parent}"/><child link="link_{i}"/>',
            f'    <origin xyz="{0.0 if i == 1 else 0.02} 0 {origin_z}" rpy="0 0 0"/>'
            f'<axis xyz="{axes[i - 1]}"/>',
            # acceleration: 0.2 s to full speed (teleop.robots.robot.ACCELERATION_RAMP_TIME)
            '    <limit lower="-3.1" upper="3.1" velocity="3.0" effort="10" acceleration="15.0"/>',
            '  </joint>',
            f'  <link name="link_{i}">',
            f'    <visual><origin xyz="0 0 {link_length / 2}"/><geometry>'
            f'<cylinder radius="0.02" length="{link_length}"/></geometry></visual>',
            '    <inertial><mass value="1"/>'
            '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>',
            '  </link>',
        ]
        parent = f"link_{i}"
    parts += [
        '  <joint name="tool0_joint" type="fixed">',
        f'    <parent link="{parent}"/><child link="tool0"/><origin xyz="0 0 {link_length}"/>',
        '  </joint>', '  <link name="tool0"/>', '</robot>']
    return "\n".join(parts) + "\n"


def load_chain(dof: int, directory: str | Path | None = None) -> Robot:
    """A generated chain as a :class:`Robot` (its URDF written to ``directory`` or a temp dir).

    Home is a gently curled pose (no straight-line singularity); the constrained link is
    the middle one, its axis z.
    """
    directory = Path(directory or tempfile.mkdtemp(prefix="cjm-chain-"))
    path = directory / f"chain{dof}.urdf"
    path.write_text(chain_urdf(dof), encoding="utf-8")
    q_home = np.array([0.4 * math.sin(1.3 * i + 0.5) for i in range(dof)])
    return load_robot(path, ee_frame="tool0", constrained_link=f"link_{max(1, dof // 2)}",
                      link_axis=(0.0, 0.0, 1.0), q_home=q_home)


def hole_links(dof: int, count: int) -> list[str]:
    """``count`` links spread along the chain for holes (never the last 2 links)."""
    if count < 1 or 2 * count + 6 > dof:
        raise ValueError(f"{count} holes need at least {2 * count + 6} joints, the chain has {dof}")
    positions = np.linspace(dof - 2, dof * 0.3, count).round().astype(int)  # first: near the tip
    return [f"link_{max(1, int(p))}" for p in positions]
