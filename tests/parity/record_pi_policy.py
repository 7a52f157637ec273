"""Record what MolmoSpaces' PI_Policy applies on every pi_policy_scenario case, for the default test suite.

    .venv/bin/python tests/parity/record_pi_policy.py     # needs .parity-venv; rewrites pi_policy_expected.json

``test_pi_policy.py`` checks our presets against this file without the parity venv, and (under
``make parity``) that the file still equals a fresh run of their code.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
EXPECTED = HERE / "pi_policy_expected.json"


def record() -> dict:
    import theirs
    from pi_policy_scenario import CASES, applied_theirs, their_inputs

    out = theirs.run("pi_policy_theirs:main", their_inputs(CASES))
    return {"molmo_spaces": theirs.run("theirs:versions")["molmo-spaces"], "end_on_success": out["end_on_success"],
            "cases": {name: applied_theirs(out, name) for name in CASES}}


if __name__ == "__main__":
    sys.path[:0] = [str(HERE), str(HERE.parent)]
    EXPECTED.write_text(json.dumps(record(), indent=1) + "\n")
    print(f"wrote {EXPECTED}")
