"""``cosmos``: an OpenC3 COSMOS plugin fragment (CONTRACT section 7).

Files (a folder, or a zip):

* ``plugin.txt`` — ``VARIABLE`` lines: the target and packet that get the items, the version,
  the document digest and every coefficient of this version;
* ``vars.json`` — the same variables as JSON (this version's values);
* ``targets/MAGCAL/cmd_tlm/magcal_tlm.txt`` — ``SELECT_TELEMETRY`` of the mission's packet and
  three ``DERIVED`` items with ``READ_CONVERSION mag_calibration.py ARGS...``, the arguments
  being ERB references to the variables;
* ``targets/MAGCAL/lib/mag_calibration.py`` — ``MagCalibration``, a subclass of
  ``openc3.conversions.conversion.Conversion`` that reads the raw axes and housekeeping items
  with ``packet.read(NAME, 'RAW')`` and applies the **whole** calibration (the network too),
  in plain Python (no numpy needed inside COSMOS).

COSMOS changes a conversion only by installing a new plugin version: a new calibration is a new
``vars.json`` (same layout) or a new fragment (new layout).
"""

from __future__ import annotations

import json

from orbitcal.export._text import f64
from orbitcal.export.names import cosmos_comment, cosmos_token
from orbitcal.export.options import ExportOptions
from orbitcal.export.product import AffineForm, NetworkForm, ProductInfo, layout

__all__ = ["CONVERSION_SOURCE", "render_cosmos"]

#: The conversion class. Arguments (strings, as COSMOS passes them): axis (0, 1, 2), layout,
#: the three raw item names, the number of housekeeping items and their names, then the
#: coefficients in the layout's order (the forms' ``coefficients()``).
CONVERSION_SOURCE = '''"""orbitcal magnetometer calibration as an OpenC3 COSMOS read conversion.

b_cal [nT] of one axis from the raw axes [nT] and housekeeping items of the same packet.
"""

import math

from openc3.conversions.conversion import Conversion


class MagCalibration(Conversion):
    def __init__(self, axis, layout, raw_x, raw_y, raw_z, n_hk, *rest):
        super().__init__()
        self.axis = int(axis)
        self.layout = str(layout)
        self.raw = [str(raw_x), str(raw_y), str(raw_z)]
        n = int(n_hk)
        self.hk = [str(h) for h in rest[:n]]
        c = [float(v) for v in rest[n:]]
        self.converted_type = "FLOAT"
        self.converted_bit_size = 64
        self.params = [axis, layout, raw_x, raw_y, raw_z, n_hk, *rest]
        parts = self.layout.split(":")
        if parts[0] == "affine":
            self._init_affine(c, n)
        elif parts[0] == "network":
            n_in = int(parts[2].split("=")[1])
            hidden = int(parts[3].split("=")[1])
            self._init_network(c, parts[1], n_in, hidden)
        else:
            raise ValueError("unknown layout " + self.layout)

    @staticmethod
    def _take(c, pos, rows, cols=None):
        if cols is None:
            return c[pos:pos + rows], pos + rows
        return [c[pos + i * cols:pos + (i + 1) * cols] for i in range(rows)], pos + rows * cols

    def _init_affine(self, c, k):
        self.kind = "affine"
        self.M, p = self._take(c, 0, 3, 3)
        self.o, p = self._take(c, p, 3)
        self.K, p = self._take(c, p, 3, k)
        if p != len(c):
            raise ValueError("expected %d coefficients, got %d" % (p, len(c)))

    def _init_network(self, c, activation, n, h):
        self.kind = "network"
        self.activation = activation
        self.in_lo, p = self._take(c, 0, n)
        self.in_gain, p = self._take(c, p, n)
        self.W1, p = self._take(c, p, h, n)
        self.b1, p = self._take(c, p, h)
        self.W2, p = self._take(c, p, 3, h)
        self.b2, p = self._take(c, p, 3)
        self.L, p = self._take(c, p, 3, n)
        self.out_lo, p = self._take(c, p, 3)
        self.out_gain, p = self._take(c, p, 3)
        if p != len(c):
            raise ValueError("expected %d coefficients, got %d" % (p, len(c)))

    def call(self, value, packet, buffer):
        x = [float(packet.read(name, "RAW")) for name in self.raw + self.hk]
        r = self.axis
        if self.kind == "affine":
            k = len(self.hk)
            b = [
                x[i] - self.o[i] - sum(self.K[i][j] * x[3 + j] for j in range(k))
                for i in range(3)
            ]
            return self.M[r][0] * b[0] + self.M[r][1] * b[1] + self.M[r][2] * b[2]
        u = [(x[i] - self.in_lo[i]) * self.in_gain[i] - (1.0 if self.in_gain[i] > 0 else 0.0)
             for i in range(len(x))]
        y = self.b2[r]
        for j in range(len(self.b1)):
            z = self.b1[j] + sum(self.W1[j][i] * u[i] for i in range(len(u)))
            hj = math.tanh(z) if self.activation == "tanh" else 1.0 / (1.0 + math.exp(-z))
            y += self.W2[r][j] * hj
        y += sum(self.L[r][i] * u[i] for i in range(len(u)))
        if self.out_gain[r] > 0:
            return (y + 1.0) / self.out_gain[r] + self.out_lo[r]
        return self.out_lo[r]

    def __str__(self):
        return "MagCalibration axis %d (%s)" % (self.axis, self.layout)

    def to_config(self, read_or_write):
        args = " ".join(str(p) for p in self.params)
        return "    %s_CONVERSION mag_calibration.py %s\\n" % (read_or_write, args)
'''


def _var(name: str) -> str:
    return "magcal_" + name.lower()


def render_cosmos(
    form: AffineForm | NetworkForm, info: ProductInfo, options: ExportOptions
) -> dict[str, bytes]:
    """The plugin fragment's files by relative path."""
    coefs = form.coefficients()
    hk_items = [options.hk_parameter(c) for c in form.hk_names]
    variables: dict[str, str] = {
        "magcal_target": options.cosmos_target,
        "magcal_packet": options.cosmos_packet,
        "magcal_version": str(info.version),
        "magcal_sha256": info.sha256,
    }
    for name, value in coefs.items():
        variables[_var(name)] = f64(value)
    header = ["# " + cosmos_comment(line) for line in info.lines()]
    header.append(
        "# carries: the whole calibration (MagCalibration evaluates the "
        + ("affine model" if isinstance(form, AffineForm) else "network")
        + "); its output equals orbitcal apply (to 1e-6 nT)"
    )
    plugin = [*header, "#", "# Merge into your plugin.txt; vars.json holds the same values."]
    plugin += [f"VARIABLE {k} {v}" for k, v in variables.items()]
    items = []
    names = [n.rsplit("/", 1)[-1] for n in options.cal_names]
    raw = [n.rsplit("/", 1)[-1] for n in options.raw_names]
    hk = [n.rsplit("/", 1)[-1] for n in hk_items]
    args_tail = " ".join(f"<%= {_var(n)} %>" for n in coefs)
    for axis, name in enumerate(names):
        items += [
            f'  ITEM {name} 0 0 DERIVED "calibrated magnetic field, axis {axis}, body frame"',
            "    UNITS nanotesla nT",
            f"    READ_CONVERSION mag_calibration.py {axis} {cosmos_token(layout(form))} "
            f"{' '.join(raw)} {len(hk)} {' '.join(hk)} {args_tail}".replace("  ", " "),
        ]
    tlm = [
        f"# orbitcal magnetometer calibration of {cosmos_comment(info.spacecraft)} "
        "(generated; do not edit),",
        f"# layout {cosmos_comment(layout(form))}: a new version of the same layout changes "
        "vars.json only.",
        "# orbitcal calibration version <%= magcal_version %>, document SHA-256 "
        "<%= magcal_sha256 %>",
        "SELECT_TELEMETRY <%= magcal_target %> <%= magcal_packet %>",
        *items,
    ]
    return {
        "plugin.txt": ("\n".join(plugin) + "\n").encode(),
        "vars.json": (json.dumps(variables, indent=2) + "\n").encode(),
        "targets/MAGCAL/cmd_tlm/magcal_tlm.txt": ("\n".join(tlm) + "\n").encode(),
        "targets/MAGCAL/lib/mag_calibration.py": CONVERSION_SOURCE.encode(),
        "README.txt": (
            "\n".join(info.lines())
            + "\n\nCopy cmd_tlm/magcal_tlm.txt and lib/mag_calibration.py into the target that "
            "defines the raw packet, merge the VARIABLE lines into plugin.txt and install the "
            "plugin (docs/export/cosmos.md).\n"
        ).encode(),
    }
