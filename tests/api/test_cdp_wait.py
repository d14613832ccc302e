"""The browser helper's wait: a page between a reload and its new document has no context to
evaluate in, and chromium says so with an error, not a value (CI at 1544911 failed on it right
after ``location.reload()``). Without chromium: ``Browser.wait_for`` on a stand-in page."""

from __future__ import annotations

from typing import Any

import pytest
from cdp import Browser, CdpError


class _Page:
    """Answers ``evaluate`` from a list: a value, or an error to raise."""

    def __init__(self, answers: list[Any]) -> None:
        self.answers = list(answers)

    def evaluate(self, expression: str) -> Any:
        answer = self.answers.pop(0)
        if isinstance(answer, Exception):
            raise answer
        return answer


@pytest.mark.parametrize(
    "message",
    [
        "Inspected target navigated or closed",
        "Cannot find context with specified id",
        "Execution context was destroyed.",
    ],
)
def test_a_page_navigating_is_waited_for(message: str) -> None:
    error = CdpError(f"Runtime.evaluate: {{'code': -32000, 'message': '{message}'}}")
    page = _Page([error, None, "ready"])
    assert Browser.wait_for(page, "document.body.dataset.ready", timeout_s=5.0) == "ready"  # type: ignore[arg-type]
    assert page.answers == []


def test_other_errors_still_fail() -> None:
    page = _Page([CdpError("Runtime.evaluate: {'code': -32601, 'message': 'no such method'}")])
    with pytest.raises(CdpError, match="no such method"):
        Browser.wait_for(page, "document.body.dataset.ready", timeout_s=5.0)  # type: ignore[arg-type]
