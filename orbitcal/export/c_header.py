"""``c-header``: an on-board table and a tiny C function that applies it (CONTRACT section 7).

The table is the affine form ``b_cal = M (b_raw - o - K hk)`` (exact for the affine methods; a
network's affine part otherwise, and the header says what that drops), in float64 and float32,
with the version, the document's SHA-256 and a CRC-32 (IEEE 802.3, as zlib's ``crc32``) of each
table's bytes in little-endian IEEE-754 order, which ``orbitcal_magcal_crc32_f64/f32`` recompute
on board (on a little-endian processor) before the table is trusted.

Table layout (row-major): ``M[0][0..2], M[1][0..2], M[2][0..2], o[0..2], K[0][0..k-1], K[1][..],
K[2][..]``.
"""

from __future__ import annotations

import struct
import zlib
from string import Template

import numpy as np

from orbitcal.export._text import f64, loss_lines
from orbitcal.export.names import c_comment, c_string
from orbitcal.export.options import ExportOptions
from orbitcal.export.product import (
    AffineForm,
    NetworkForm,
    ProductInfo,
    affine_part,
    is_exact_affine,
)

__all__ = ["render_c_header", "table_crc32"]


def _table(form: AffineForm) -> list[float]:
    return [
        *np.asarray(form.M, dtype=np.float64).reshape(-1).tolist(),
        *np.asarray(form.o, dtype=np.float64).tolist(),
        *np.asarray(form.K, dtype=np.float64).reshape(-1).tolist(),
    ]


def table_crc32(values: list[float], *, single: bool) -> int:
    """CRC-32 of the table as little-endian float32 (``single``) or float64 bytes."""
    fmt = "<" + ("f" if single else "d") * len(values)
    return zlib.crc32(struct.pack(fmt, *values)) & 0xFFFFFFFF


def _f32_literal(value: float) -> str:
    v = float(np.float32(value))
    return repr(v) + "f" if "e" in repr(v) or "." in repr(v) else repr(v) + ".0f"


#: One apply function, written once for each precision ($T the C type, $S the suffix).
_APPLY = Template(
    """static inline void orbitcal_magcal_apply_$S(const $T raw[3], const $T hk[], $T out[3])
{
    const $T *M = orbitcal_magcal_table_$S;
    const $T *o = orbitcal_magcal_table_$S + 9;
    const $T *K = orbitcal_magcal_table_$S + 12;
    $T b[3];
    int i, j;
    for (i = 0; i < 3; i++) {
        $T s = raw[i] - o[i];
        for (j = 0; j < ORBITCAL_MAGCAL_N_HK; j++) s -= K[i * ORBITCAL_MAGCAL_N_HK + j] * hk[j];
        b[i] = s;
    }
    for (i = 0; i < 3; i++) out[i] = M[3 * i] * b[0] + M[3 * i + 1] * b[1] + M[3 * i + 2] * b[2];
}
"""
)

_CODE = (
    "\n" + "/* b_cal = M (b_raw - o - K hk) [nT]; raw in nT, "
    "hk in the table units of the column names. */\n"
    + _APPLY.substitute(T="double", S="f64")
    + "\n"
    + _APPLY.substitute(T="float", S="f32")
    + "\n"
    + """/* CRC-32 (IEEE 802.3, reflected, poly 0xEDB88320) of n bytes. */
static inline uint32_t orbitcal_magcal_crc32(const unsigned char *p, size_t n)
{
    uint32_t crc = 0xFFFFFFFFu;
    size_t i;
    int k;
    for (i = 0; i < n; i++) {
        crc ^= p[i];
        for (k = 0; k < 8; k++) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
    }
    return crc ^ 0xFFFFFFFFu;
}

/* 1 when the tables in memory match their CRCs (little-endian IEEE-754 processors). */
static inline int orbitcal_magcal_table_ok(void)
{
    return orbitcal_magcal_crc32((const unsigned char *)orbitcal_magcal_table_f64,
                                 sizeof orbitcal_magcal_table_f64) == ORBITCAL_MAGCAL_CRC32_F64
        && orbitcal_magcal_crc32((const unsigned char *)orbitcal_magcal_table_f32,
                                 sizeof orbitcal_magcal_table_f32) == ORBITCAL_MAGCAL_CRC32_F32;
}
"""
)


def render_c_header(
    form: AffineForm | NetworkForm, info: ProductInfo, options: ExportOptions
) -> bytes:
    """The header file ``orbitcal_magcal.h`` as bytes."""
    aff = affine_part(form)
    exact = is_exact_affine(form)
    values = _table(aff)
    k = len(aff.hk_names)
    carries = "the affine form b_cal = M (b_raw - o - K hk)" + (
        ""
        if isinstance(form, AffineForm)
        else " (the network's expansion about its inputs' centre)"
    )
    comment = info.lines() + loss_lines(
        info, carries=carries, exact=exact, loss=options.loss, which="affine"
    )
    comment.append(
        "float32 table and function: coefficients and arithmetic rounded to float32 "
        "(relative 6e-8 per operation; about 0.01 nT at 50,000 nT, docs/export/results.md); "
        "the float64 ones carry the table exactly"
    )
    comment.append(
        "hk inputs, in order: " + (", ".join(aff.hk_names) if aff.hk_names else "(none)")
    )
    lines = ["/* orbitcal magnetometer calibration table (generated; do not edit)."]
    lines += [f" * {c_comment(c)}" for c in comment]
    lines.append(" */")
    lines += [
        "#ifndef ORBITCAL_MAGCAL_H",
        "#define ORBITCAL_MAGCAL_H",
        "#include <stddef.h>",
        "#include <stdint.h>",
        "",
        f"#define ORBITCAL_MAGCAL_VERSION {info.version}",
        f'#define ORBITCAL_MAGCAL_SPACECRAFT "{c_string(info.spacecraft)}"',
        f'#define ORBITCAL_MAGCAL_METHOD "{c_string(info.method)}"',
        f'#define ORBITCAL_MAGCAL_SHA256 "{c_string(info.sha256)}"',
        f'#define ORBITCAL_MAGCAL_VALIDITY_START "{c_string(info.validity_start)}"',
        f"#define ORBITCAL_MAGCAL_N_HK {k}",
        f"#define ORBITCAL_MAGCAL_TABLE_LEN {len(values)}",
        f"#define ORBITCAL_MAGCAL_CRC32_F64 0x{table_crc32(values, single=False):08X}u",
        f"#define ORBITCAL_MAGCAL_CRC32_F32 0x{table_crc32(values, single=True):08X}u",
        "",
        f"static const double orbitcal_magcal_table_f64[{len(values)}] = {{",
        *[f"    {f64(v)}," for v in values],
        "};",
        f"static const float orbitcal_magcal_table_f32[{len(values)}] = {{",
        *[f"    {_f32_literal(v)}," for v in values],
        "};",
        _CODE,
        "#endif /* ORBITCAL_MAGCAL_H */",
    ]
    return ("\n".join(lines) + "\n").encode()
