"""The shipped cylinder_contact_force.gcode on the IPAnema 3 in the in-process closed loop (nominal
plant = robot file, controller parameters of params/ipanema3.yaml) against a barrel around the
programmed path, with M103/M104 as the program says (the set-up of the test
test_cylinder_program_presses_follows_and_releases): prints the state sequence, the contact force
error along the surface normal while moving in state D and the cable force range; the surface
stiffness and friction are arguments (docs/hybrid_force_control.md, "Following").

    python scripts/cylinder_contact_run.py [stiffness N/m] [friction]     (about 50 s simulated)
"""
import itertools
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_hybrid_force_control import IPANEMA3, cylinder_program_run  # noqa: E402


def main(stiffness: float = 1e6, friction: float = 0.3) -> None:
    r, states, F_n, F_d, moving = cylinder_program_run(stiffness, friction)
    print("states:", " ".join(f"{s}({len(list(g))} ms)" for s, g in itertools.groupby(states)))
    error = np.abs(F_n[moving] - F_d[moving])
    print(f"moving in contact {moving.sum() * 1e-3:.1f} s: |F - F_d| max {error.max():.1f} N, "
          f"rms {np.sqrt(np.mean(error ** 2)):.1f} N, 99th percentile {np.percentile(error, 99):.1f} N")
    c = IPANEMA3.cable
    print(f"cable forces {r.f.min():.1f} .. {r.f.max():.1f} N (limits {c.f_min.min():.0f} .. {c.f_max.max():.0f} N); "
          f"end pose {np.round(r.x[-1, :3], 4)} for {np.round(r.x_d[-1, :3], 4)}")


if __name__ == "__main__":
    main(*map(float, sys.argv[1:3]))
