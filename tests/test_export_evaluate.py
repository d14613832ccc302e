"""The calibration product (issue 21): the numpy reference evaluator reproduces ``orbitcal apply``
for every method, the affine part is exact where it should be, the digest is canonical, and the
held-out figures the exports state are the document's own where they can be."""

from __future__ import annotations

import json
import subprocess
import sys
from typing import Any

import numpy as np
import pytest
from export_worlds import ALL_METHODS, EXACT_NT, fitted
from hypothesis import given
from hypothesis import strategies as st

from orbitcal.calibrate.errors import DocumentError
from orbitcal.errors import BadInputError
from orbitcal.export import (
    ExportError,
    ExportOptions,
    NetworkForm,
    affine_part,
    calibration_form,
    document_sha256,
    evaluate,
    evaluate_document,
    held_out_loss,
    parse_hk_names,
    parse_names,
    product_info,
)


@pytest.mark.parametrize("method", ALL_METHODS)
def test_reference_evaluator_equals_apply(method: str, swarm_a_temperature_world: Any) -> None:
    f = fitted(swarm_a_temperature_world, method)
    b = evaluate_document(f.document, f.telemetry.b_raw_nt, f.x_hk)
    assert np.max(np.abs(b - f.b_apply_nt)) < EXACT_NT
    # the calibration does something: it is not the identity on this sensor
    assert np.max(np.abs(b - f.telemetry.b_raw_nt)) > 10.0


@pytest.mark.parametrize("method", ["linear", "linear-hk", "twostep", "flann", "online"])
def test_affine_methods_are_their_own_affine_part(
    method: str, swarm_a_temperature_world: Any
) -> None:
    f = fitted(swarm_a_temperature_world, method)
    form = calibration_form(f.document)
    assert affine_part(form) is form
    # and the document's linear block is M, o of that form
    assert np.array_equal(np.asarray(f.document["linear"]["M"]), form.M)


def test_network_affine_part_is_the_tangent_at_the_inputs_centre(
    swarm_a_temperature_world: Any,
) -> None:
    f = fitted(swarm_a_temperature_world, "lmbp-hk")
    form = calibration_form(f.document)
    assert isinstance(form, NetworkForm)
    aff = affine_part(form)
    # at the centre of the input box the expansion equals the network, and its slope is the
    # network's (central differences, 1 nT steps on raw inputs)
    x0 = form.in_lo + np.where(
        form.in_gain > 0, 1.0 / np.where(form.in_gain > 0, form.in_gain, 1), 0
    )
    raw0, hk0 = x0[None, :3], x0[None, 3:]
    assert np.max(np.abs(evaluate(aff, raw0, hk0) - evaluate(form, raw0, hk0))) < 1e-6
    for j in range(3):
        step = np.zeros((1, 3))
        step[0, j] = 1.0
        slope_net = (evaluate(form, raw0 + step, hk0) - evaluate(form, raw0 - step, hk0)) / 2
        assert np.allclose(slope_net[0], aff.M[:, j], atol=1e-6)


def test_network_with_hidden_layer_off_is_exactly_affine(swarm_a_temperature_world: Any) -> None:
    f = fitted(swarm_a_temperature_world, "lmbp-hk")
    doc = json.loads(json.dumps(f.document))
    W2 = np.asarray(doc["model"]["weights"]["W2"])
    doc["model"]["weights"]["W2"] = np.zeros_like(W2).tolist()
    from orbitcal.calibrate.document import calibration_from_document

    cal = calibration_from_document(doc)
    b = cal.apply(f.telemetry.b_raw_nt, f.x_hk)
    form = calibration_form(doc)
    assert np.max(np.abs(evaluate(affine_part(form), f.telemetry.b_raw_nt, f.x_hk) - b)) < EXACT_NT


def test_document_digest_is_canonical() -> None:
    doc = {"b": [1.0, 2.5e-17], "a": {"z": "µT", "y": 3}}
    same = json.loads(json.dumps(doc, indent=4))
    assert document_sha256(doc) == document_sha256(same)
    import hashlib

    expected = hashlib.sha256('{"a":{"y":3,"z":"µT"},"b":[1.0,2.5e-17]}'.encode()).hexdigest()
    assert document_sha256(doc) == expected
    assert document_sha256({**doc, "b": [1.0, 2.6e-17]}) != expected


def test_product_names_what_the_contract_asks(swarm_a_temperature_world: Any) -> None:
    f = fitted(swarm_a_temperature_world, "linear-hk")
    info = product_info(f.document)
    assert (info.spacecraft, info.version, info.method) == ("swarm-a", 1, "linear-hk")
    assert info.reference_field == "IGRF-14"
    assert info.validity_start == f.document["created_at"]
    assert info.sha256 == document_sha256(f.document) and len(info.sha256) == 64
    assert "body frame" in info.frame and info.units.startswith("nT")
    assert (
        "sensor axes" in product_info(fitted(swarm_a_temperature_world, "twostep").document).frame
    )


@pytest.mark.parametrize("method", ["linear-hk", "lmbp-hk", "twostep"])
def test_held_out_loss_of_the_whole_model_is_the_documents(
    method: str, swarm_a_temperature_world: Any
) -> None:
    f = fitted(swarm_a_temperature_world, method)
    loss = held_out_loss(f.document, f.telemetry, orbit=f.orbit)
    assert loss.n_samples == int(f.document["metrics"]["n_holdout"])
    assert loss.full_rms_nt == pytest.approx(f.document["metrics"]["holdout_rms_nt"], rel=1e-9)
    if method == "lmbp-hk":
        assert loss.affine_rms_nt > loss.full_rms_nt and loss.affine_max_abs_diff_nt > 0.1
    if method == "linear-hk":
        assert loss.affine_rms_nt == loss.full_rms_nt and loss.affine_max_abs_diff_nt == 0.0
        # the diagonal drops the magnetorquer and temperature terms: hundreds of nT here
        assert loss.diagonal_rms_nt > 10 * loss.full_rms_nt


def test_missing_housekeeping_is_a_clear_error(swarm_a_temperature_world: Any) -> None:
    f = fitted(swarm_a_temperature_world, "linear-hk")
    with pytest.raises(BadInputError, match="temperature"):
        evaluate_document(f.document, f.telemetry.b_raw_nt, None)
    with pytest.raises(BadInputError, match="5 housekeeping columns"):
        evaluate_document(f.document, f.telemetry.b_raw_nt, np.zeros((len(f.telemetry), 2)))


def test_malformed_documents_and_options_are_named() -> None:
    with pytest.raises(DocumentError, match="lmbp"):
        calibration_form({"method": "lmbp", "model": {"hk_names": []}})
    with pytest.raises(DocumentError, match="cannot read"):
        product_info({"method": "linear"})
    with pytest.raises(ExportError, match="unknown export format 'yaml'"):
        ExportOptions(format="yaml")
    with pytest.raises(ExportError, match="three names"):
        parse_names("A,B", ("X", "Y", "Z"), "--raw-names")
    with pytest.raises(ExportError, match="not a parameter name"):
        parse_names("A,B C,D", ("X", "Y", "Z"), "--raw-names")
    with pytest.raises(ExportError, match="must differ"):
        ExportOptions(raw_names=("A", "B", "C"), cal_names=("C", "D", "E"))
    with pytest.raises(ExportError, match="COLUMN=NAME"):
        parse_hk_names("temperature")
    assert parse_hk_names("temperature=T_MAG, mtq_x=/SAT/MTQ_X") == {
        "temperature": "T_MAG",
        "mtq_x": "/SAT/MTQ_X",
    }


def test_evaluator_needs_no_torch() -> None:
    code = (
        "import sys, json, numpy as np\n"
        "from orbitcal.export import evaluate_document\n"
        "doc = {'method': 'lmbp', 'model': {'hk_names': [], 'n_hidden': 1, 'activation': 'tanh',"
        " 'linear_path': False, 'input_scaler': {'min': [0, 0, 0], 'max': [1, 1, 1]},"
        " 'output_scaler': {'min': [0, 0, 0], 'max': [2, 2, 2]}, 'weights': {'W1': [[1, 0, 0]],"
        " 'b1': [0], 'W2': [[1], [0], [0]], 'b2': [0, 0, 0]}}}\n"
        "print(evaluate_document(doc, np.array([[0.5, 0.5, 0.5]])).tolist())\n"
        "assert 'torch' not in sys.modules, 'torch was imported'\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    # u = 0 -> h = 0 -> y = 0 -> b = (0 + 1) / 1 + 0 = 1 on every axis
    assert json.loads(out.stdout) == [[1.0, 1.0, 1.0]]


def test_public_surface() -> None:
    import orbitcal.export as ex

    assert sorted(ex.__all__) == sorted(
        [
            "DEFAULT_CAL_NAMES",
            "DEFAULT_RAW_NAMES",
            "FORMATS",
            "AffineForm",
            "ExportError",
            "ExportOptions",
            "ExportResult",
            "HeldOutLoss",
            "NetworkForm",
            "ProductInfo",
            "YamcsTarget",
            "affine_part",
            "calibration_form",
            "document_sha256",
            "evaluate",
            "evaluate_document",
            "export",
            "held_out_loss",
            "hk_columns",
            "parse_hk_names",
            "parse_names",
            "product_info",
        ]
    )
    assert ex.FORMATS == (
        "json",
        "xtce",
        "yamcs-push",
        "yamcs-instance",
        "cosmos",
        "c-header",
        "polynomial",
    )
    assert ex.DEFAULT_RAW_NAMES == ("MAG_X_RAW", "MAG_Y_RAW", "MAG_Z_RAW")
    assert ex.DEFAULT_CAL_NAMES == ("MAG_X_CAL", "MAG_Y_CAL", "MAG_Z_CAL")


@given(
    n_hidden=st.integers(1, 4),
    n_hk=st.integers(0, 3),
    activation=st.sampled_from(["tanh", "sigmoid"]),
    linear_path=st.booleans(),
    constant_column=st.booleans(),
    seed=st.integers(0, 2**32 - 1),
)
def test_evaluator_equals_the_torch_network_on_random_networks(
    n_hidden: int, n_hk: int, activation: str, linear_path: bool, constant_column: bool, seed: int
) -> None:
    """Any network the document format can hold (sizes, activations, a constant input or
    output column whose scaler maps to 0): the numpy evaluator equals LMBPCalibration.apply."""
    from orbitcal.calibrate.document import calibration_from_document

    rng = np.random.default_rng(seed)
    n_in = 3 + n_hk
    lo_in = rng.normal(scale=3e4, size=n_in)
    hi_in = lo_in + rng.uniform(1.0, 6e4, size=n_in)
    lo_out = rng.normal(scale=3e4, size=3)
    hi_out = lo_out + rng.uniform(1.0, 6e4, size=3)
    if constant_column:
        hi_in[-1] = lo_in[-1]
        hi_out[1] = lo_out[1]
    weights = {
        "W1": rng.normal(size=(n_hidden, n_in)).tolist(),
        "b1": rng.normal(size=n_hidden).tolist(),
        "W2": rng.normal(size=(3, n_hidden)).tolist(),
        "b2": rng.normal(size=3).tolist(),
    }
    if linear_path:
        weights["L"] = rng.normal(size=(3, n_in)).tolist()
    hk = [f"hk_c{j}" for j in range(n_hk)]
    doc: dict[str, Any] = {
        "method": "lmbp-hk" if n_hk else "lmbp",
        "linear": {"M": np.eye(3).tolist(), "o": [0.0, 0.0, 0.0]},
        "model": {
            "n_hidden": n_hidden,
            "activation": activation,
            "linear_path": linear_path,
            "hk_names": hk,
            "input_scaler": {"min": lo_in.tolist(), "max": hi_in.tolist()},
            "output_scaler": {"min": lo_out.tolist(), "max": hi_out.tolist()},
            "weights": weights,
        },
    }
    x = lo_in + rng.uniform(-0.2, 1.2, size=(50, n_in)) * (hi_in - lo_in)
    b_raw, x_hk = x[:, :3], (x[:, 3:] if n_hk else None)
    expected = calibration_from_document(doc).apply(b_raw, x_hk)
    got = evaluate_document(doc, b_raw, x_hk)
    assert np.max(np.abs(got - expected)) < EXACT_NT
    if linear_path and not constant_column:
        # (the affine formats need M invertible: with a linear path, as lmbp-hk has, it is; a
        # constant output or fewer than 3 hidden units without one make it singular: refused)
        form = calibration_form(doc)
        assert isinstance(form, NetworkForm)
        x0 = form.in_lo + 1.0 / form.in_gain  # the centre of the input box: u = 0
        c0 = x0[None, :3], (x0[None, 3:] if n_hk else None)
        assert np.max(np.abs(evaluate(affine_part(form), *c0) - evaluate(form, *c0))) < 1e-6
        step = 1e-5 / form.in_gain[0]  # central difference along raw x (u moves by 1e-5)
        d = np.zeros((1, 3))
        d[0, 0] = step
        slope = (evaluate(form, c0[0] + d, c0[1]) - evaluate(form, c0[0] - d, c0[1])) / (2 * step)
        assert np.allclose(slope[0], affine_part(form).M[:, 0], rtol=1e-6, atol=1e-9)
