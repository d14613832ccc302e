"""``create_app`` in named parts with one typed state object (issue 23, the service's share)."""

from __future__ import annotations

from pathlib import Path

from fastapi.testclient import TestClient
from pydantic import SecretStr

from service.app import create_app, new_state, refuse_unsafe_settings
from service.http import (
    HeaderChecks,
    HttpLimits,
    LimitedH11Protocol,
    LimitedHttpToolsProtocol,
    uvicorn_options,
)
from service.settings import Settings
from service.state import ServiceState


def _settings(tmp_path: Path, **overrides: object) -> Settings:
    return Settings(
        database_url=f"sqlite:///{tmp_path / 'app.sqlite'}",
        admin_key=SecretStr("k"),
        scheduler=False,
        **overrides,  # type: ignore[arg-type]
    )


def test_the_state_is_one_typed_object_made_with_the_app_and_opened_by_the_lifespan(
    tmp_path: Path,
) -> None:
    app = create_app(_settings(tmp_path))
    state = app.state
    assert isinstance(state, ServiceState)
    assert state.settings.admin_key is not None and state.admin_key_hash is not None
    assert state.key_cache == {} and state.calibration_cache == {}
    assert "engine" not in vars(state)["_state"]  # opened by the lifespan, not before
    with TestClient(app) as http:
        assert http.get("/healthz").status_code == 200
        assert state.engine is not None and state.metrics is not None
        assert state.leader in (True, False) and state.diagnoses is not None
        assert http.get("/v1/spacecraft", headers={"X-API-Key": "k"}).json() == []


def test_unsafe_settings_are_refused_before_anything_is_built(tmp_path: Path) -> None:
    import pytest

    with pytest.raises(ValueError, match="without authentication"):
        refuse_unsafe_settings(_settings(tmp_path, auth=False, bind_host="0.0.0.0"))
    state = new_state(_settings(tmp_path))
    assert isinstance(state, ServiceState) and state.diagnoses.latest(("any", False)) is None


def test_the_server_is_given_the_limits_of_the_settings(tmp_path: Path) -> None:
    settings = _settings(tmp_path, max_header_bytes=32 * 1024, shutdown_timeout_s=2.5)
    options = uvicorn_options(settings)
    assert options["http"] is LimitedHttpToolsProtocol  # the default
    assert LimitedHttpToolsProtocol.limits == HttpLimits.from_settings(settings)
    h11_options = uvicorn_options(_settings(tmp_path, http_protocol="h11", max_header_bytes=2048))
    assert h11_options["http"] is LimitedH11Protocol
    assert LimitedH11Protocol.limits == HttpLimits.from_settings(
        _settings(tmp_path, http_protocol="h11", max_header_bytes=2048)
    )
    assert options["timeout_graceful_shutdown"] == 3
    assert options["h11_max_incomplete_event_size"] > 32 * 1024
    assert options["proxy_headers"] is False  # the app applies FORWARDED_ALLOW_IPS itself
    app = create_app(settings)
    assert any(m.cls is HeaderChecks for m in app.user_middleware)
