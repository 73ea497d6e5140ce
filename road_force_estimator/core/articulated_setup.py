"""One articulated drive's configuration from its parameters: what ``simulate_bag`` and the
``plant_simulator`` node both build (the same numbers from the same file).

:meth:`ArticulatedDrive.from_values` checks the names (:func:`.articulated_parameters.
check_model_names`), builds the vehicle, the model (its statics refuse a vehicle that cannot
stand), the speed and lateral profiles, and holds what the plant and the sensors need.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterable, Mapping, Sequence

from road_force_estimator.core.articulated_model import ArticulatedModel
from road_force_estimator.core.articulated_parameters import ArticulatedParameters
from road_force_estimator.core.articulated_plant import ArticulatedPlant
from road_force_estimator.core.articulated_sensors import ArticulatedSensors
from road_force_estimator.core.lateral_profile import LateralProfile, parse_lateral_profile
from road_force_estimator.core.parameters import ARTICULATED_SPECS, SimulatorParameters
from road_force_estimator.core.road import RoadProfile
from road_force_estimator.core.speed_profile import (
    profile_distance, read_speed_profile, speed_knots)

__all__ = ['ArticulatedDrive']


@dataclass(frozen=True)
class ArticulatedDrive:
    """An articulated drive's vehicle, model, simulator settings and profiles."""

    vehicle: ArticulatedParameters
    sim: SimulatorParameters
    model: ArticulatedModel
    speed_profile: tuple | None
    lateral: LateralProfile | None
    imu_noise: tuple[float, float]

    @classmethod
    def from_values(cls, values: Mapping[str, Any], given: Iterable[str] | None = None,
                    lateral: LateralProfile | None = None) -> ArticulatedDrive:
        """From ``{dotted name: value}`` (``given``: the names the user set, default the
        keys); ``lateral`` replaces ``simulator.lateral_profile`` (simulate_bag's
        ``--lateral-acceleration``).

        Raises
        ------
        ValueError
            One line: a refused name or value, a vehicle that cannot stand, a bad profile.
        """
        vehicle = ArticulatedParameters.from_parameters(values, given)
        sim = SimulatorParameters.from_parameters(values)
        model = ArticulatedModel.from_vehicle_springs(vehicle)
        profile = read_speed_profile(sim.speed_profile) if sim.speed_profile else None
        if lateral is None:
            lateral = parse_lateral_profile(sim.lateral_profile)
        noise = tuple(float(values.get(name, ARTICULATED_SPECS[name].default)) for name in (
            'simulator.noise.imu_acceleration', 'simulator.noise.imu_rate'))
        return cls(vehicle, sim, model, profile, lateral, noise)

    @property
    def instrumented_axles(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.vehicle.axles if a.instrumented)

    @property
    def travel_m(self) -> float:
        """The front axle's distance over ``simulator.duration`` (m)."""
        sim = self.sim
        if self.speed_profile is None:
            return sim.speed_mps * sim.duration_s
        return float(profile_distance(speed_knots(*self.speed_profile), sim.duration_s))

    @property
    def road_length_m(self) -> float:
        """The road a synthetic source must give: the travel, the vehicle's length behind the
        front axle, the tire envelope at both ends and a metre."""
        return (self.travel_m + self.model.length_m + 2.0 * self.sim.tire_envelope_length_m
                + 1.0)

    def plant(self, road: RoadProfile, **options) -> ArticulatedPlant:
        """The plant on ``road`` with the drive's speed, lateral acceleration, envelope,
        crossfall and the sliders' start."""
        sim = self.sim
        return ArticulatedPlant(
            self.vehicle, road, speed_mps=sim.speed_mps, rate_hz=sim.rate_hz,
            speed_profile=self.speed_profile, lateral_acceleration=self.lateral,
            tire_envelope_m=sim.tire_envelope_length_m, crossfall_rad=sim.road_crossfall_rad,
            friction_start=sim.leaf_spring_friction_start, model=self.model, **options)

    def sensors(self, names: Sequence[str]) -> ArticulatedSensors:
        """The sensors (channels named ``names``, the contract's) with the IMU's noise."""
        sensors = ArticulatedSensors(self.model, self.sim, names)
        sensors.set_imu_noise(*self.imu_noise)
        return sensors
