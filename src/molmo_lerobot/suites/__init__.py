"""Env suites: benchmarks whose episodes run in an external Gymnasium env (LeRobot's LIBERO first) rather than a
scene built here, each in its own virtualenv behind a small msgpack pipe protocol (docs/suites.md)."""
