"""The constant-speed sweep both friction test scripts drive (friction_sweep.py: one joint at a
time on a hand-written drive; arm_sweep.py: a 4-joint arm in MuJoCo): for each joint, each speed,
both directions, a settle at the reference and a trapezoid (accelerate, cruise, brake).

`advance(j, profile, secs)` is the script's own: it runs joint j along `profile(s) -> (position,
velocity, acceleration)` for `secs` (or holds the reference when `profile` is None), logging
what the sensors see.
"""


def trapezoid(start, sign, speed, cruise, accel):
    """A move from `start` in direction `sign`: ramp to `speed` at `accel`, cruise `cruise` s,
    ramp down. Returns (profile, duration in s)."""
    ramp = speed / accel

    def profile(s):
        if s < ramp:
            return (start + sign * 0.5 * accel * s * s, sign * accel * s, sign * accel)
        d_ramp = 0.5 * speed * ramp
        if s < ramp + cruise:
            return (start + sign * (d_ramp + speed * (s - ramp)), sign * speed, 0.0)
        r = min(s - ramp - cruise, ramp)
        return (
            start + sign * (d_ramp + speed * cruise + speed * r - 0.5 * accel * r * r),
            sign * (speed - accel * r),
            -sign * accel if r < ramp else 0.0,
        )

    return profile, 2 * ramp + cruise


def sweep(n_joints, speeds, ref, advance, accel, stroke, max_cruise, settle):
    """Every joint through every speed, both ways; `ref[j]` (position, velocity, acceleration)
    follows each move's end."""
    for j in range(n_joints):
        for speed in speeds:
            cruise = min(max_cruise, (stroke - speed * speed / accel) / speed)
            for sign in (1.0, -1.0):
                advance(j, None, settle)
                profile, secs = trapezoid(ref[j][0], sign, speed, cruise, accel)
                advance(j, profile, secs)
                ref[j] = (profile(secs)[0], 0.0, 0.0)
        advance(j, None, settle)
