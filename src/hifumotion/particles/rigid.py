"""Rigid bodies made of particles (the paper's Eq. 17), SI units.

A body keeps its particles' offsets in its own frame. Each step the forces on
its particles (coupling, pressure, gravity) are summed to a total force and,
by Eq. 17, a torque ``τ = Σ (x_i − x_c) × f_i`` about the centre of mass; an
applied external force (the pushing bar's: constant or a time schedule) acts
at the centre of mass along a given direction. Translation is integrated as
``v += dt F/M``, rotation through the angular momentum ``L += dt τ`` with
``ω = R I_body⁻¹ Rᵀ L`` and the orientation quaternion advanced by the exact
rotation ``exp(ω dt)`` — so a torque-free body keeps L to round-off.

Constraints: ``axis`` (only translation along a unit vector, no rotation: a
bar in a guide) and ``fixed``; ``prescribed_velocity_m_s`` moves a body at a
given velocity whatever the forces (for indentation tests), recording the
reaction it meets.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import numpy as np

from hifumotion.scene.schedule import ForceSchedule


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion ``(w, x, y, z)``."""
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ])


def rotation_quaternion(rotation_vector: np.ndarray) -> np.ndarray:
    """Unit quaternion of a rotation by ``|θ|`` about ``θ/|θ|`` (rad)."""
    angle = float(np.linalg.norm(rotation_vector))
    if angle < 1e-300:
        return np.array([1.0, 0.0, 0.0, 0.0])
    axis = rotation_vector / angle
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])


@dataclass
class RigidBody:
    """One rigid body: particles ``first … first + len(offsets_m) − 1`` of the system.

    Attributes (SI)
    ---------------
    offsets_m
        Particle offsets from the centre of mass in the body frame (m).
    masses_kg
        Particle masses (kg).
    centre_m, velocity_m_s, orientation, angular_momentum
        State: centre of mass (m), its velocity (m/s), unit quaternion (w, x, y, z)
        body → world, angular momentum about the centre (kg·m²/s).
    force_n
        Applied external force magnitude (N) as a function of time (s).
    force_direction
        Unit vector the applied force acts along.
    axis
        If set, the body only translates along this unit vector and does not rotate.
    fixed
        The body does not move (it still feels forces, reported as reaction).
    prescribed_velocity_m_s
        If set, the body moves at this velocity whatever the forces.
    weight_supported
        Gravity does not act on the body (a hand or a guide carries its weight), so the
        applied force alone pushes what it touches.
    """

    first: int
    offsets_m: np.ndarray
    masses_kg: np.ndarray
    centre_m: np.ndarray
    velocity_m_s: np.ndarray = field(default_factory=lambda: np.zeros(3))
    orientation: np.ndarray = field(default_factory=lambda: np.array([1.0, 0, 0, 0]))
    angular_momentum: np.ndarray = field(default_factory=lambda: np.zeros(3))
    force_n: ForceSchedule = lambda t: 0.0
    force_direction: np.ndarray = field(default_factory=lambda: np.zeros(3))
    axis: np.ndarray | None = None
    fixed: bool = False
    prescribed_velocity_m_s: np.ndarray | None = None
    weight_supported: bool = False
    name: str = "bar"
    last_particle_force_n: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def from_particles(cls, first: int, positions_m: np.ndarray, masses_kg: np.ndarray,
                       **kwargs) -> "RigidBody":
        """A body at rest from its particles' world positions (m) and masses (kg)."""
        x = np.asarray(positions_m, float)
        m = np.asarray(masses_kg, float)
        centre = (m[:, None] * x).sum(0) / m.sum()
        return cls(first=first, offsets_m=x - centre, masses_kg=m, centre_m=centre, **kwargs)

    def __post_init__(self):
        self.offsets_m = np.asarray(self.offsets_m, float)
        self.masses_kg = np.asarray(self.masses_kg, float)
        self.centre_m = np.asarray(self.centre_m, float).copy()
        self.force_direction = np.asarray(self.force_direction, float)
        if self.axis is not None:
            a = np.asarray(self.axis, float)
            self.axis = a / np.linalg.norm(a)
        r = self.offsets_m
        m = self.masses_kg
        # inertia tensor from the particles (each a point mass)
        rr = (r * r).sum(1)
        self.inertia_body = (m[:, None, None] * (rr[:, None, None] * np.eye(3)
                                                 - r[:, :, None] * r[:, None, :])).sum(0)
        self.inverse_inertia_body = np.linalg.pinv(self.inertia_body)

    @property
    def count(self) -> int:
        return len(self.offsets_m)

    @property
    def mass_kg(self) -> float:
        return float(self.masses_kg.sum())

    def rotation(self) -> np.ndarray:
        return quaternion_to_matrix(self.orientation)

    def angular_velocity(self) -> np.ndarray:
        """ω = R I_body⁻¹ Rᵀ L (rad/s)."""
        r = self.rotation()
        return r @ self.inverse_inertia_body @ r.T @ self.angular_momentum

    def kinetic_energy(self) -> float:
        """Translational plus rotational kinetic energy (J)."""
        return 0.5 * self.mass_kg * float(self.velocity_m_s @ self.velocity_m_s) + \
            0.5 * float(self.angular_velocity() @ self.angular_momentum)

    def particle_states(self) -> tuple[np.ndarray, np.ndarray]:
        """World positions (m) and velocities (m/s) of the body's particles."""
        arm = self.offsets_m @ self.rotation().T
        return self.centre_m + arm, self.velocity_m_s + np.cross(self.angular_velocity(), arm)

    def step(self, particle_forces_n: np.ndarray, gravity_m_s2: np.ndarray, time_s: float,
             dt_s: float, mass_scaling: float = 1.0) -> None:
        """Advance by ``dt_s`` under Eq. 17's total force and torque plus the applied force.

        ``particle_forces_n`` are the interaction forces on the body's particles (N).
        Gravity acts on the true mass; ``mass_scaling`` multiplies the inertia only.
        """
        arm = self.offsets_m @ self.rotation().T
        total = particle_forces_n.sum(0)
        self.last_particle_force_n = total
        torque = np.cross(arm, particle_forces_n).sum(0)           # Eq. 17
        weight = 0.0 if self.weight_supported else self.mass_kg
        total = total + weight * np.asarray(gravity_m_s2) + self.force_n(time_s) * self.force_direction
        if self.fixed:
            return
        if self.prescribed_velocity_m_s is not None:
            self.velocity_m_s = np.asarray(self.prescribed_velocity_m_s, float)
            self.centre_m = self.centre_m + dt_s * self.velocity_m_s
            return
        inertia = self.mass_kg * mass_scaling
        self.velocity_m_s = self.velocity_m_s + dt_s * total / inertia
        if self.axis is not None:
            self.velocity_m_s = float(self.velocity_m_s @ self.axis) * self.axis
            self.centre_m = self.centre_m + dt_s * self.velocity_m_s
            return
        self.centre_m = self.centre_m + dt_s * self.velocity_m_s
        self.angular_momentum = self.angular_momentum + dt_s * torque
        omega = self.angular_velocity() / mass_scaling
        self.orientation = quaternion_multiply(rotation_quaternion(omega * dt_s), self.orientation)
        self.orientation /= np.linalg.norm(self.orientation)
