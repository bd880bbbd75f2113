"""Settings of the servo (:class:`ServoParams`), grouped by the stage they set: the
registration, the control law, the stop rule, the watchdog, the sensor faults, the
relocalization, the recovery and the plane turn (:mod:`spectral_vs.servo.stage_settings`,
:mod:`spectral_vs.servo.fault_settings`).
Every setting is also a keyword and an attribute of :class:`ServoParams` itself
(``ServoParams(max_outage=0.3)``, ``params.max_outage``)."""

from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from spectral_vs._core import AlignParams
from spectral_vs.servo.fault_settings import FaultParams, RecoveryParams, RelocalizationParams
from spectral_vs.servo.setting_checks import check_keys
from spectral_vs.servo.stage_settings import (
    LawParams,
    PlaneTurnParams,
    RegistrationParams,
    StopParams,
    WatchdogParams,
)

#: The groups of :class:`ServoParams`: attribute name and settings type.
_GROUPS: dict[str, type] = {
    "registration": RegistrationParams,
    "law": LawParams,
    "stop": StopParams,
    "watchdog": WatchdogParams,
    "faults": FaultParams,
    "relocalization": RelocalizationParams,
    "recovery": RecoveryParams,
    "plane": PlaneTurnParams,
}
#: The group of every setting, by its name.
_GROUP_OF: dict[str, str] = {
    item.name: group for group, kind in _GROUPS.items() for item in dataclasses.fields(kind)
}


@dataclass(init=False)
class ServoParams:
    """Settings of :class:`~spectral_vs.servo.SpectralServo`, one group a stage.

    Every setting of a group is also a keyword of the constructor and an attribute of
    :class:`ServoParams` (read and written through to its group):
    ``ServoParams(voxel_size=0.01, max_outage=0.3)`` equals
    ``ServoParams(registration=RegistrationParams(voxel_size=0.01),
    faults=FaultParams(max_outage=0.3))``, and ``params.max_outage`` is
    ``params.faults.max_outage``. A keyword that is no setting raises TypeError.

    Attributes
    ----------
    registration : RegistrationParams
        The registration of each step.
    law : LawParams
        The decoupled control law and its speed limits.
    stop : StopParams
        The stop rule and its hysteresis.
    watchdog : WatchdogParams
        The watchdog on jumps of the estimate.
    faults : FaultParams
        The holds on sensor faults and the outage that stops the servo.
    relocalization : RelocalizationParams
        The global registration when the servo has no trusted estimate.
    recovery : RecoveryParams
        The recovery when the global registration cannot register the view.
    plane : PlaneTurnParams
        The plane turn and the dominant plane.
    """

    registration: RegistrationParams = field(default_factory=RegistrationParams)
    law: LawParams = field(default_factory=LawParams)
    stop: StopParams = field(default_factory=StopParams)
    watchdog: WatchdogParams = field(default_factory=WatchdogParams)
    faults: FaultParams = field(default_factory=FaultParams)
    relocalization: RelocalizationParams = field(default_factory=RelocalizationParams)
    recovery: RecoveryParams = field(default_factory=RecoveryParams)
    plane: PlaneTurnParams = field(default_factory=PlaneTurnParams)

    def __init__(self, **settings: Any) -> None:
        flat: dict[str, dict[str, Any]] = {group: {} for group in _GROUPS}
        given: dict[str, Any] = {}
        for name, value in settings.items():
            if name in _GROUPS:
                given[name] = value
            elif name in _GROUP_OF:
                flat[_GROUP_OF[name]][name] = value
            else:
                raise TypeError(f"ServoParams() got an unexpected keyword argument {name!r}")
        for group, kind in _GROUPS.items():
            if group not in given:
                value = kind(**flat[group])
            elif not isinstance(given[group], kind):
                raise TypeError(
                    f"ServoParams() {group} must be a {kind.__name__}, "
                    f"got {type(given[group]).__name__}"
                )
            else:  # a copy: two settings never share a group
                value = dataclasses.replace(given[group], **flat[group])
            object.__setattr__(self, group, value)

    def __getattr__(self, name: str) -> Any:
        """A setting read through its group (``params.max_outage``)."""
        group = _GROUP_OF.get(name)
        if group is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        return getattr(object.__getattribute__(self, group), name)

    def __setattr__(self, name: str, value: Any) -> None:
        """A setting written through to its group (``params.max_outage = 0.3``)."""
        group = _GROUP_OF.get(name)
        if group is not None:
            setattr(getattr(self, group), name, value)
        elif name in _GROUPS:
            object.__setattr__(self, name, value)
        else:
            raise AttributeError(f"{type(self).__name__!r} object has no setting {name!r}")

    def __copy__(self) -> ServoParams:
        return ServoParams(**{group: copy.copy(getattr(self, group)) for group in _GROUPS})

    def uses_tracking(self) -> bool:
        """True when the locked-on registration uses ``tracking_translation``."""
        bounded = self.align_params().max_translation > 0
        return (
            bounded
            and 0 < self.registration.tracking_translation < self.registration.max_translation
        )

    def resolved(self, reference: Any) -> ServoParams:
        """A copy with every scale length given as 0 derived from ``reference`` (the cloud
        at the desired pose, camera frame, m): the settings a
        :class:`~spectral_vs.servo.SpectralServo` of that reference uses
        (:func:`spectral_vs.servo.scale.resolve_scale`)."""
        from spectral_vs.clouds import as_cloud
        from spectral_vs.servo.scale import resolve_scale

        return resolve_scale(self, as_cloud(reference, "reference"))[0]

    def align_params(self) -> AlignParams:
        """The :class:`AlignParams` of one registration in this mode; the scale lengths
        must be resolved (:meth:`resolved`)."""
        if self.registration.voxel_size == 0:
            raise ValueError(
                "voxel_size is 0 (derived from the reference): call align_params() on "
                "ServoParams.resolved(reference)"
            )
        params = AlignParams()
        params.voxel_size = self.registration.voxel_size
        params.bandwidth = self.registration.bandwidth
        params.max_rotation_step = self.registration.max_rotation_step
        params.initial_guess = np.eye(4)
        # The servo reads only the fitness: no pose verification (2 ms per step).
        params.verify = False
        unbounded = (
            self.registration.mode == "pose" and self.registration.global_search
        ) or math.isinf(self.registration.max_translation)
        params.max_translation = 0.0 if unbounded else self.registration.max_translation
        if self.registration.mode == "iteration":
            params.global_search = False
            params.max_iterations = 1
            params.translation_gain = 1.0
            params.rotation_gain = 1.0
        else:
            params.global_search = self.registration.global_search
            params.max_iterations = self.registration.max_iterations
            params.refinement_iterations = (
                self.registration.max_iterations
            )  # the global search's runs
        for name, value in self.registration.align_overrides.items():
            check_keys({name: value}, "align_overrides", AlignParams)
            setattr(params, name, value)
        return params
