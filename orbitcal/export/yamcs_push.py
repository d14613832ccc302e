"""``yamcs-push``: set a running Yamcs's coefficient parameters to this calibration.

Uses the Yamcs HTTP API (``yamcs-api`` ``processing.proto``):

1. ``POST /api/processors/{instance}/{processor}/parameters:batchGet`` of ``/<SYS>/<SYS>_LAYOUT``
   and ``/<SYS>/<SYS>_VERSION``: the MDB loaded must have been generated for the same layout
   (same method family, hidden size and housekeeping inputs); otherwise the push refuses and
   says to load the new XTCE;
2. ``POST /api/processors/{instance}/{processor}/parameters:batchSet`` with one
   ``{"id": {"name": "/<SYS>/<NAME>"}, "value": {"type": "DOUBLE", "doubleValue": v}}`` per
   coefficient (then ``_SHA256`` and ``_VERSION`` last, so a reader that sees the new version
   sees its coefficients).

A push lasts until the next restart of Yamcs: the XTCE marks every coefficient
``persistence="false"``, so after a (re)start the coefficients are the loaded file's, with or
without ``persistParameters`` (the version rule, docs/yamcs.md; tested against a real Yamcs in
tests/test_export_yamcs_real.py). The report says so. Credentials go as HTTP Basic
authentication (Yamcs ``HttpHandler``).
"""

from __future__ import annotations

from typing import Any

from orbitcal.export.options import ExportError, ExportOptions, YamcsTarget
from orbitcal.export.product import AffineForm, NetworkForm, ProductInfo
from orbitcal.export.xtce import coefficient_values

__all__ = ["push_to_yamcs", "set_request"]


def _value(v: float | int | str) -> dict[str, Any]:
    if isinstance(v, str):
        return {"type": "STRING", "stringValue": v}
    if isinstance(v, int):
        return {"type": "UINT32", "uint32Value": v}
    return {"type": "DOUBLE", "doubleValue": float(v)}


def set_request(
    form: AffineForm | NetworkForm, info: ProductInfo, options: ExportOptions
) -> dict[str, Any]:
    """The ``batchSet`` body: coefficients first, then the digest and the version."""
    sys_ = options.space_system
    values = coefficient_values(form, info, options)
    last = [f"{sys_}_LAYOUT", f"{sys_}_SHA256", f"{sys_}_VERSION"]
    order = [n for n in values if n not in last] + last
    return {
        "request": [
            {"id": {"name": f"/{sys_}/{name}"}, "value": _value(values[name])} for name in order
        ]
    }


def _base(target: YamcsTarget) -> str:
    url = target.url.rstrip("/")
    if not url.startswith(("http://", "https://")):
        raise ExportError(
            f"Yamcs URL must start with http:// or https://: {url!r}", field="yamcs_url"
        )
    return f"{url}/api/processors/{target.instance}/{target.processor}"


def push_to_yamcs(
    form: AffineForm | NetworkForm,
    info: ProductInfo,
    options: ExportOptions,
    *,
    transport: Any = None,
) -> dict[str, Any]:
    """Set the coefficients on the Yamcs of ``options.yamcs``; return what was set.

    Raises
    ------
    ExportError
        No target, an unreachable server, an error answer, or an MDB of another layout.
    """
    import httpx

    from orbitcal.export.product import layout

    target = options.yamcs
    if target is None:
        raise ExportError("yamcs-push needs a Yamcs URL and instance", field="yamcs_url")
    base = _base(target)
    sys_ = options.space_system
    auth = (
        httpx.BasicAuth(target.username, target.password or "")
        if target.username is not None
        else None
    )
    body = set_request(form, info, options)
    want = layout(form)
    try:
        with httpx.Client(timeout=target.timeout_s, auth=auth, transport=transport) as client:
            got = client.post(
                f"{base}/parameters:batchGet",
                json={
                    "id": [{"name": f"/{sys_}/{sys_}_LAYOUT"}, {"name": f"/{sys_}/{sys_}_VERSION"}],
                    "fromCache": True,
                },
            )
            if got.status_code != 200:
                raise ExportError(
                    f"Yamcs answered {got.status_code} to batchGet of /{sys_}/{sys_}_LAYOUT: "
                    f"{got.text[:200]} (is the orbitcal XTCE loaded in instance "
                    f"{target.instance!r}?)",
                    field="yamcs_url",
                )
            previous: dict[str, Any] = {}
            for pv in got.json().get("value", []):
                name = str(pv.get("id", {}).get("name", ""))
                eng = pv.get("engValue", {})
                previous[name.rsplit("/", 1)[-1]] = eng.get(
                    "stringValue", eng.get("uint32Value", eng.get("sint64Value"))
                )
            loaded = previous.get(f"{sys_}_LAYOUT")
            if loaded != want:
                raise ExportError(
                    f"the Yamcs MDB holds layout {loaded!r} and this calibration needs {want!r}: "
                    "load the new XTCE export (orbitcal export --format xtce) first",
                    field="layout",
                )
            answer = client.post(f"{base}/parameters:batchSet", json=body)
            if answer.status_code not in (200, 204):
                raise ExportError(
                    f"Yamcs answered {answer.status_code} to batchSet: {answer.text[:200]}",
                    field="yamcs_url",
                )
    except httpx.HTTPError as exc:
        raise ExportError(f"cannot reach Yamcs at {target.url}: {exc}", field="yamcs_url") from exc
    return {
        "orbitcal_export": "yamcs-push",
        "product": info.to_json(),
        "yamcs": {"url": target.url, "instance": target.instance, "processor": target.processor},
        "previous_version": previous.get(f"{sys_}_VERSION"),
        "layout": want,
        "set": {
            r["id"]["name"]: next(iter(v for k, v in r["value"].items() if k != "type"))
            for r in body["request"]
        },
        "n_set": len(body["request"]),
        "lasts": "until the next restart of Yamcs, which serves the loaded MDB file's version "
        "again; to keep this version, load its XTCE (docs/yamcs.md)",
    }
