"""Secrets out of log records and texts (``security/redact.py``), and the token store's checks off the
event loop (``TokenStore.verify_async``): what each promises, on its own."""

from __future__ import annotations

import asyncio
import logging

import pytest

from wott_hub.security import Scope, TokenFile, TokenStore
from wott_hub.security.redact import install_log_redaction, redact
from wott_hub.security.tokens import MAX_PENDING_CHECKS, TooManyChecks, split_token

TOKEN = "wott_0123abcd_Zm9vYmFyYmF6cXV4LV9mb29iYXJiYXpxdXgtX2Zvbw"


@pytest.mark.parametrize(("text", "kept"), [
    (f"GET /things?access_token={TOKEN}&x=1", "GET /things?access_token=[redacted]&x=1"),
    (f"token {TOKEN} refused", "token wott_0123abcd_[redacted] refused"),
    ("Authorization: Bearer abcdefghijklmnopqrstuvwxyz0123", "Authorization: Bearer [redacted]"),
    ('WWW-Authenticate: Bearer realm="wott-hub"', 'WWW-Authenticate: Bearer realm="wott-hub"'),
    ("nothing secret here", "nothing secret here"),
])
def test_redact_keeps_what_is_not_secret(text, kept):
    assert redact(text) == kept


def test_every_log_record_is_redacted_message_arguments_and_traceback(caplog):
    install_log_redaction()
    log = logging.getLogger("wott_hub.test_redact")
    with caplog.at_level(logging.INFO, logger="wott_hub.test_redact"):
        log.info("request %s", f"/wot/hub?access_token={TOKEN}")
        try:
            raise ValueError(f"bad {TOKEN}")
        except ValueError:
            log.exception("failed")
    secret = split_token(TOKEN)[1]
    assert secret not in caplog.text
    assert "access_token=[redacted]" in caplog.text and "wott_0123abcd_[redacted]" in caplog.text


def test_verify_async_answers_like_verify_and_bounds_its_queue(tmp_path):
    f = TokenFile(tmp_path / "t.json")
    token, _ = f.create("a", Scope.READ)
    tid, _ = split_token(token)

    async def scenario() -> None:
        store = TokenStore(file=f.path)
        assert (await store.verify_async(token)).name == "a"
        assert store.known(token) == (True, store.verify(token))  # remembered: no hash
        wrong = f"wott_{tid}_{'x' * 43}"
        assert await store.verify_async(wrong) is None
        assert store.known(wrong) == (True, None)  # a wrong one too
        flood = [store.verify_async(f"wott_{tid}_{i:043d}") for i in range(MAX_PENDING_CHECKS + 8)]
        results = await asyncio.gather(*flood, return_exceptions=True)
        refused = [r for r in results if isinstance(r, TooManyChecks)]
        assert len(refused) == 8 and all(r is None for r in results if not isinstance(r, TooManyChecks))
        assert store.refusals == 8

    asyncio.run(scenario())


def test_a_broken_token_file_keeps_the_last_good_set(tmp_path, monkeypatch, caplog):
    import wott_hub.security.tokens as tokens

    monkeypatch.setattr(tokens, "_RELOAD_EVERY_S", 0.0)
    f = TokenFile(tmp_path / "t.json")
    token, _ = f.create("a", Scope.READ)
    store = TokenStore(file=f.path)
    f.path.write_text('{"tokens": [')
    with caplog.at_level(logging.WARNING, logger="wott_hub.security"):
        assert store.verify(token).name == "a"
        assert store.verify(token).name == "a"
    assert len([r for r in caplog.records if "keeping the 1 token(s)" in r.getMessage()]) == 1
    f.path.write_text('{"tokens": []}')
    assert store.verify(token) is None  # a good file again: read, the token is gone
