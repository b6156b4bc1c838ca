"""The lumped model's standard run on the field string with axial elements and the RGD bit.

At each operating point P1-P4 of ``drill_env.coupled.STANDARD_POINTS`` (RGD-A bit), the
``field_2500m`` string has its top drive held at ``Omega_0`` and the applied force ``W_0`` at
its top, from steady drilling with the bit at ``0.9 Omega_0``; the features over ``[100, 400]
s`` are printed beside the lumped model's (``drill_env.coupled.standard_run``). Run:
``OMP_NUM_THREADS=1 .venv/bin/python -m experiments.field_coupled_points`` (about 1.5 min of
CPU).
"""

from __future__ import annotations

import numpy as np

from drill_env.coupled import STANDARD_DURATION_S, STANDARD_POINTS, STANDARD_WINDOW_S, standard_run
from drill_env.coupled_chain import FieldCoupledTrace, simulate_field


def features(trace: FieldCoupledTrace, speed: float) -> tuple[float, float, float, float]:
    """Stuck and off-rock fractions, ``(max - min) Omega / (2 Omega_0)`` and ``ROP / V_0``
    over the standard window."""
    t1, t2 = STANDARD_WINDOW_S
    window = (trace.time_s >= t1 - 1e-9) & (trace.time_s <= t2 + 1e-9)
    om = trace.bit_speed_rad_s[window]
    depth = trace.depth_m[window]
    rop = (depth[-1] - depth[0]) / (t2 - t1)
    return (
        float(np.mean(trace.stuck[window][1:])),
        float(np.mean(trace.off_bottom[window][1:])),
        float(om.max() - om.min()) / (2 * speed),
        rop / trace.steady.rate_of_penetration_m_s,
    )


def main() -> None:
    print("point  model        frac_stick  frac_bounce  Om_amp_rel  ROP_rel")
    for point, (force, speed) in STANDARD_POINTS.items():
        _, lumped = standard_run("rgd_a", point)
        print(
            f"{point:5}  lumped       {lumped.frac_stick:10.3f}  {lumped.frac_bounce:11.3f}  "
            f"{lumped.om_amp_rel:10.3f}  {lumped.rop_rel:7.3f}"
        )
        trace = simulate_field("field_2500m", speed, force, STANDARD_DURATION_S)
        stick, bounce, amp, rop = features(trace, speed)
        print(f"{point:5}  field_2500m  {stick:10.3f}  {bounce:11.3f}  {amp:10.3f}  {rop:7.3f}")


if __name__ == "__main__":
    main()
