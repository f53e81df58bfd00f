"""The gate of ``servodesk serve`` (app/web_gate.py) as a table: which Host, Origin and token
it lets through. Served for real, with sessions, in tests/app/test_serve.py."""

from __future__ import annotations

import pytest

from app.web_gate import Gate

LOCAL = Gate.listening_on("127.0.0.1")


@pytest.mark.parametrize("host", ["127.0.0.1:8000", "localhost:9000", "LOCALHOST:8000",
                                  "[::1]:8000", "127.0.0.2:8000"])
def test_a_name_or_loopback_address_of_this_machine_passes(host) -> None:
    assert LOCAL.host_problem(host) == ""  # another port: an SSH forward's


@pytest.mark.parametrize("host", ["rebound.example:8000", "10.0.0.5:8000", "", None,
                                  "127.0.0.1:notaport:1"])
def test_a_foreign_or_missing_host_is_refused(host) -> None:
    assert LOCAL.host_problem(host) != ""


def test_listening_on_every_address_any_address_passes_but_no_foreign_name() -> None:
    every = Gate.listening_on("0.0.0.0")
    assert every.host_problem("10.0.0.5:8000") == ""
    assert "not a name of this server" in every.host_problem("rebound.example:8000")
    assert every.page_url("0.0.0.0", 8000).startswith("http://127.0.0.1:8000/?token=")


@pytest.mark.parametrize("origin", ["http://127.0.0.1:8000", "HTTP://127.0.0.1:8000"])
def test_the_page_s_own_origin_passes(origin) -> None:
    assert LOCAL.origin_problem(origin, "127.0.0.1:8000") == ""


@pytest.mark.parametrize("origin", ["http://attacker.example", "http://127.0.0.1:8001",
                                    "http://attacker.example:8000", "null", "", None,
                                    "file://127.0.0.1:8000"])
def test_another_or_no_origin_is_refused(origin) -> None:
    assert LOCAL.origin_problem(origin, "127.0.0.1:8000") != ""


def test_only_the_token_passes_and_each_gate_has_its_own() -> None:
    assert LOCAL.token_problem(LOCAL.token) == ""
    assert "needs servodesk serve's token" in LOCAL.token_problem(None)
    for wrong in (LOCAL.token[:-1], LOCAL.token + "x", "é" * 10):
        assert "wrong token" in LOCAL.token_problem(wrong)
    assert Gate.listening_on("127.0.0.1").token != LOCAL.token
    assert LOCAL.token not in repr(LOCAL)
