"""The pose servo: the operator's targets to each EE's commanded body twist (docs/design.md 5.1).

For every end effector ``i``, one period::

    T*_f,i <- T*_f,i exp6(alpha log6(T*_f,i^-1 T*_i)),  alpha = 1 - exp(-dt/tau)   smoothing
    V_ff,i  = log6(T*_f,i,prev^-1 T*_f,i) / dt                                  the target's twist
    V_e,i   = K_p log6(T_e,i^-1 T*_f,i) + Ad_(T_e,i^-1 T*_f,i) V_ff,i            pose gain + feed-forward
    V_e,i  <- V_e,i min(1, v_max/|v|, w_max/|w|)                                the speed caps

(the first period, or ``tau = 0``: ``T*_f,i = T*_i``; the first period has no feed-forward).
Its state is the filtered targets and the previous period's. A controller that runs the
loop's period in C++ (``controller.loop_tick``, the compiled CJM's
:class:`~controllers.cjm.compiled_tick.CompiledTick`) computes the same in its kernel; while
the kernel runs the periods, the state lives there, and this object is the one place that
hands it over, to the kernel before its first period and back before a period in Python.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple, Protocol, Sequence

import numpy as np
import pinocchio as pin

from .loop_config import LoopConfig
from .targets import saturate_twist

class ServoKernel(Protocol):
    """The compiled period that computes the servo in C++ (what ``controller.loop_tick``
    returns, docs/design.md 5.1): whether the controller's step can take the period
    (``ready``), the constraints' violations it measures at ``q`` (``sense``), one period
    (``run``), its last stacked twist after the caps, and the filter's state as poses."""

    controller: Any
    twist: np.ndarray | None

    def ready(self) -> bool: ...

    def sense(self, q: np.ndarray) -> list[float] | None: ...

    def history(self) -> tuple[list[pin.SE3] | None, list[pin.SE3] | None]: ...

    def set_history(self, filtered: Sequence[pin.SE3] | None,
                    previous: Sequence[pin.SE3] | None) -> None: ...

    def run(self, poses: Sequence[pin.SE3], q: np.ndarray, integrate: bool) -> Any: ...


class ServoPeriod(NamedTuple):
    """One period of the servo in Python: the filtered targets, the previous period's
    (None on the first: no feed-forward), each EE's twist after the caps, and whether a
    cap scaled one."""

    targets: list[pin.SE3]
    previous: list[pin.SE3] | None
    twists: list[np.ndarray]
    saturated: bool


class PoseServo:
    """Targets to EE body twists (module docstring): the filter, the pose-to-twist law and
    the speed caps of ``config`` (:class:`LoopConfig`: ``dt``, ``kp``, the caps, ``tau``,
    ``feed_forward``), with the filter's state, for ``ee_count`` end effectors."""

    def __init__(self, config: LoopConfig, ee_count: int) -> None:
        if not isinstance(config, LoopConfig):
            raise ValueError(f"config must be a LoopConfig, got {type(config).__name__}")
        if isinstance(ee_count, bool) or not isinstance(ee_count, int) or ee_count < 1:
            raise ValueError(f"ee_count must be a positive integer, got {ee_count!r}")
        self.config = config
        self.ee_count = ee_count
        tau = config.target_time_constant
        #: the smoothing's step towards the target, ``1 - exp(-dt/tau)`` (None: tau = 0, none)
        self.alpha = None if tau == 0.0 else 1.0 - math.exp(-config.dt / tau)
        self._filtered: list[pin.SE3] | None = None
        self._previous: list[pin.SE3] | None = None
        #: the compiled period computing the servo (None: Python alone)
        self.kernel: ServoKernel | None = None
        self._holder: ServoKernel | None = None  # the kernel while the state lives there

    def attach_kernel(self, controller: Any) -> ServoKernel | None:
        """``controller.loop_tick`` for this servo's settings, kept as :attr:`kernel`; None
        (and no kernel) when the controller offers none, or when the one it offers is
        another object's (a wrapper handing its attributes on, whose own ``solve`` must be
        called)."""
        loop_tick = getattr(controller, "loop_tick", None)
        config = self.config
        kernel = None if loop_tick is None else loop_tick(
            config.dt, config.kp, config.max_linear_speed, config.max_angular_speed,
            config.target_time_constant, config.feed_forward)
        self._take_back()
        self.kernel = kernel if kernel is not None and kernel.controller is controller else None
        return self.kernel

    # -- the state -----------------------------------------------------------------

    @property
    def filtered(self) -> list[pin.SE3] | None:
        """The filtered targets of the last period (None before the first)."""
        if self._holder is not None:
            return self._holder.history()[0]
        return self._filtered

    @property
    def previous(self) -> list[pin.SE3] | None:
        """The filtered targets of the period before the next one (its feed-forward;
        None at the start)."""
        if self._holder is not None:
            return self._holder.history()[1]
        return self._previous

    def reset(self) -> None:
        """Forget the targets: the next period is a first one."""
        self._filtered = self._previous = None
        self._holder = None

    def hold(self, ee: int, pose: pin.SE3) -> None:
        """EE ``ee``'s filtered target and its feed-forward at ``pose``: the next period
        asks it no motion but towards ``pose`` (docs/design.md 19.2). The lists the earlier
        periods returned are not changed. ``ValueError`` (nothing changed) unless ``ee`` is
        in ``range(ee_count)``."""
        if isinstance(ee, bool) or not isinstance(ee, (int, np.integer)) \
                or not 0 <= ee < self.ee_count:
            raise ValueError(f"ee must be an EE index in range({self.ee_count}), got {ee!r}")
        holder = self._holder
        self._take_back()
        filtered, previous = self._filtered, self._previous
        if filtered is not None:
            filtered = [pose.copy() if i == ee else target for i, target in enumerate(filtered)]
        if previous is not None:
            previous = [pose.copy() if i == ee else target for i, target in enumerate(previous)]
        self._filtered, self._previous = filtered, previous
        if holder is not None:
            self._hand_over(holder)

    def _take_back(self) -> None:
        """The state from the kernel, when it lives there."""
        if self._holder is not None:
            self._filtered, self._previous = self._holder.history()
            self._holder = None

    def _hand_over(self, kernel: ServoKernel) -> None:
        """The state to ``kernel``."""
        kernel.set_history(self._filtered, self._previous)
        self._holder = kernel

    # -- one period ------------------------------------------------------------------

    def run_kernel(self, poses: Sequence[pin.SE3], q: np.ndarray, integrate: bool) -> Any:
        """The kernel's period (``kernel.run``) towards ``poses`` at ``q``, the state handed
        to it first when it lives here; ``ValueError`` without a kernel
        (:meth:`attach_kernel`)."""
        kernel = self.kernel
        if kernel is None:
            raise ValueError("the pose servo has no kernel: attach_kernel found none")
        if self._holder is not kernel:
            self._hand_over(kernel)
        return kernel.run(poses, q, integrate)

    def period(self, poses: Sequence[pin.SE3], placements: Sequence[pin.SE3]) -> ServoPeriod:
        """One period in Python towards ``poses`` with the EEs at ``placements`` (one
        ``pin.SE3`` each per EE): the filter, the law (:meth:`twists`), the caps
        (:meth:`cap`); the filtered targets become the next period's previous ones.
        ``ValueError`` (nothing changed) unless there is one pose and placement per EE."""
        if len(placements) != self.ee_count:
            raise ValueError(f"expected {self.ee_count} EE placements, got {len(placements)}")
        self._take_back()
        previous = self._previous
        targets = self.filter(poses)
        requested = self.twists(placements, targets, previous)
        twists = [self.cap(twist) for twist in requested]
        saturated = any(capped is not twist for capped, twist in zip(twists, requested))
        self._previous = targets  # filter makes a new list of new poses: no copy needed
        return ServoPeriod(targets, previous, twists, saturated)

    def filter(self, poses: Sequence[pin.SE3]) -> list[pin.SE3]:
        """The filtered targets after ``poses`` (first-order smoothing on SE(3), module
        docstring; the poses themselves on the first period or with ``tau = 0``); the
        filter's state advances."""
        self._take_back()
        if len(poses) != self.ee_count:
            raise ValueError(f"expected {self.ee_count} target poses, got {len(poses)}")
        alpha = self.alpha
        if self._filtered is None or alpha is None:
            self._filtered = [pose.copy() for pose in poses]
        else:
            self._filtered = [filtered * pin.exp6(pin.log6(filtered.actInv(pose)).vector * alpha)
                              for filtered, pose in zip(self._filtered, poses)]
        return self._filtered

    def twists(self, placements: Sequence[pin.SE3], targets: Sequence[pin.SE3],
               previous: Sequence[pin.SE3] | None) -> list[np.ndarray]:
        """Each EE's body twist ``K_p log6(T_e^-1 T*_f) + Ad_(T_e^-1 T*_f) V_ff`` before the
        caps, with ``V_ff = log6(T*_f,prev^-1 T*_f) / dt`` from ``previous`` (none when
        None or ``feed_forward`` is off)."""
        if len(placements) != self.ee_count or len(targets) != self.ee_count:
            raise ValueError(f"expected {self.ee_count} EE placements and targets, got "
                             f"{len(placements)} and {len(targets)}")
        kp, dt = self.config.kp, self.config.dt
        feed_forward = self.config.feed_forward and previous is not None
        twists = []
        for i, (ee, target) in enumerate(zip(placements, targets)):
            error = ee.actInv(target)
            twist = kp * pin.log6(error).vector
            if feed_forward:
                target_twist = pin.log6(previous[i].actInv(target)).vector / dt
                twist += error.action @ target_twist
            twists.append(twist)
        return twists

    def cap(self, twist: np.ndarray) -> np.ndarray:
        """``twist`` scaled uniformly within the speed caps (:func:`saturate_twist`; the
        same object when it is within both)."""
        return saturate_twist(twist, self.config.max_linear_speed,
                              self.config.max_angular_speed)
