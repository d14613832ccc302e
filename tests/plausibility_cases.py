"""The inputs that parse but are not physical (issue 44 item 9), built once for both doors.

``tests/test_plausibility.py`` (library and CLI) and ``tests/api/test_service_plausibility.py``
(HTTP) feed the same cases: a table in nT (the control), the same field in Tesla, Gauss and µT,
with two axes swapped, with one axis stuck, and with the elements of another spacecraft. Each
implausible case must be named in the words of :data:`SAYS`.
"""

from __future__ import annotations

import numpy as np

CASES = ("nT (control)", "Tesla", "Gauss", "µT", "swapped axis", "wrong spacecraft", "stuck axis")
#: What each case's refusal or warning must say.
SAYS = {
    "Tesla": "looks like Tesla: scale by 1e9",
    "Gauss": "looks like Gauss: scale by 1e5",
    "µT": "looks like µT: scale by 1e3",
    "swapped axis": "two sensor axes are swapped",
    "wrong spacecraft": "the orbit elements do not match the data",
    "stuck axis": "vary in only 2 of 3",
}
#: The factor that turns a field in nT into the same field in each other unit.
UNIT_SCALE = {"Tesla": 1e-9, "Gauss": 1e-5, "µT": 1e-3}


def case_field(b_nt: np.ndarray, case: str) -> np.ndarray:
    """The field columns ``(N, 3)`` of ``case`` made from the plausible ones ``b_nt``: scaled
    into another unit, two axes swapped, or the third axis stuck at its first value. The cases
    whose field is the plausible one (the control, the wrong spacecraft) get ``b_nt`` itself."""
    if case in UNIT_SCALE:
        return b_nt * UNIT_SCALE[case]
    if case == "swapped axis":
        return np.ascontiguousarray(b_nt[:, [1, 0, 2]])
    if case == "stuck axis":
        return np.c_[b_nt[:, :2], np.full(len(b_nt), b_nt[0, 2])]
    return b_nt
