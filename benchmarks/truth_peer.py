"""The peer of ``orbitcal truth`` as a whole process: Skyfield (SGP4, frames) + chaosmagpy (IGRF).

Run:  python benchmarks/truth_peer.py TELEMETRY.csv TLE OUT.csv

Does what ``orbitcal truth TELEMETRY --tle TLE --out OUT.csv`` does, with the packages a user would
reach for instead (no orbitcal import): pandas reads the table; Skyfield's ``EarthSatellite``
propagates the TLE with SGP4 and gives ITRS positions and the ITRS→GCRS rotation at every sample;
chaosmagpy synthesises IGRF-14 (the same ``IGRF14.shc`` that ppigrf ships and orbitcal reads) at
each sample's own time and position, in chunks of 20,000 samples; the NEC vector is turned into
ITRS, then GCRS, then the body frame with the table's quaternions (SciPy, scalar first in the
table); pandas writes ``time,b_x,b_y,b_z``. ``benchmarks/startup.py`` times it beside orbitcal.
"""

from __future__ import annotations

import sys
import warnings
from importlib import resources

import chaosmagpy
import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation
from skyfield.api import EarthSatellite, load
from skyfield.framelib import itrs

CHUNK = 20_000


def main(telemetry: str, tle: str, out: str) -> None:
    df = pd.read_csv(telemetry)
    t_utc = pd.to_datetime(df["time"], utc=True)
    with open(tle) as f:
        lines = [ln for ln in f.read().splitlines() if ln.strip()]
    ts = load.timescale(builtin=True)
    sat = EarthSatellite(lines[-2], lines[-1], lines[0] if len(lines) == 3 else None, ts)
    t = ts.from_datetimes(t_utc.dt.to_pydatetime())
    r_itrs_km = sat.at(t).frame_xyz(itrs).km.T  # (N, 3)
    rot_itrs_to_gcrs = np.moveaxis(itrs.rotation_at(t), -1, 0).transpose(0, 2, 1)  # (N, 3, 3)

    radius_km = np.linalg.norm(r_itrs_km, axis=1)
    colat_rad = np.arccos(r_itrs_km[:, 2] / radius_km)
    lon_rad = np.arctan2(r_itrs_km[:, 1], r_itrs_km[:, 0])
    shc = str(resources.files("ppigrf").joinpath("IGRF14.shc"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = chaosmagpy.chaos.BaseModel.from_shc(shc)
    mjd2000 = (t_utc - pd.Timestamp("2000-01-01", tz="UTC")).dt.total_seconds().to_numpy() / 86400
    b_nec = np.empty((len(df), 3))
    for a in range(0, len(df), CHUNK):
        b = slice(a, a + CHUNK)
        coeffs = model.synth_coeffs(mjd2000[b])
        br, bt, bp = chaosmagpy.model_utils.synth_values(
            coeffs, radius_km[b], np.degrees(colat_rad[b]), np.degrees(lon_rad[b])
        )
        b_nec[b] = np.column_stack([-bt, bp, -br])

    # NEC unit vectors in ITRS at each position.
    st, ct = np.sin(colat_rad), np.cos(colat_rad)
    sl, cl = np.sin(lon_rad), np.cos(lon_rad)
    north = np.column_stack([-ct * cl, -ct * sl, st])
    east = np.column_stack([-sl, cl, np.zeros_like(sl)])
    centre = -r_itrs_km / radius_km[:, None]
    b_itrs = b_nec[:, :1] * north + b_nec[:, 1:2] * east + b_nec[:, 2:] * centre
    b_gcrs = np.einsum("nij,nj->ni", rot_itrs_to_gcrs, b_itrs)
    q_wxyz = df[["q_w", "q_x", "q_y", "q_z"]].to_numpy()
    body_to_gcrs = Rotation.from_quat(q_wxyz[:, [1, 2, 3, 0]])
    b_body = body_to_gcrs.inv().apply(b_gcrs)
    pd.DataFrame(
        {"time": df["time"], "b_x": b_body[:, 0], "b_y": b_body[:, 1], "b_z": b_body[:, 2]}
    ).to_csv(out, index=False)


if __name__ == "__main__":
    main(*sys.argv[1:4])
