"""Run inside the test's network namespace: make the requests given as JSON, print what came back.

argv[1]: a JSON list of {"id", "method", "url", "token"?, "query_token"?, "body"?, "cafile"?,
"ws"?: true (a WebSocket handshake), "sse"?: true (read the first bytes of a stream), "until"?: text
(with "sse": read the stream until it has come)}.
Prints one JSON object {id: {"status", "www", "body", "error"}}. Standard library and tornado only:
it runs with the hub's interpreter but talks to the hub only over the veth pair.
"""

from __future__ import annotations

import asyncio
import http.client
import json
import ssl
import sys
from urllib.parse import urlsplit


def _ctx(cafile: str | None) -> ssl.SSLContext | None:
    return ssl.create_default_context(cafile=cafile) if cafile else None


def http_request(r: dict) -> dict:
    u = urlsplit(r["url"])
    path = u.path + (f"?{u.query}" if u.query else "")
    # generous: a loaded machine answers late; only a stream that is admitted and stays silent (the
    # directory's events, which send their headers with the first event) waits the SSE bound out
    timeout = 10 if r.get("sse") and not r.get("until") else 60
    if u.scheme == "https":
        conn = http.client.HTTPSConnection(u.hostname, u.port, timeout=timeout, context=_ctx(r.get("cafile")))
    else:
        conn = http.client.HTTPConnection(u.hostname, u.port, timeout=timeout)
    headers = {"Accept": "text/event-stream" if r.get("sse") else "application/json"}
    if r.get("token"):
        headers["Authorization"] = f"Bearer {r['token']}"
    if r.get("origin"):
        headers["Origin"] = r["origin"]
    body = r.get("body")
    if body is not None:
        headers["Content-Type"] = r.get("content_type", "application/json")
        body = json.dumps(body).encode()
    try:
        conn.request(r["method"], path, body=body, headers=headers)
        resp = conn.getresponse()
        if r.get("until"):  # a stream read until this text has come (or the timeout)
            data = b""
            while r["until"].encode() not in data and (more := resp.read1(4096)):
                data += more
        else:
            data = resp.read1(64) if r.get("sse") else resp.read()
        return {"status": resp.status, "www": resp.getheader("WWW-Authenticate"),
                "cors": resp.getheader("Access-Control-Allow-Origin"),
                "body": data.decode("utf-8", "replace")}
    except Exception as e:  # the test asserts on it (a refused certificate)
        return {"error": f"{type(e).__name__}: {e}"}
    finally:
        conn.close()


async def ws_request(r: dict) -> dict:
    from tornado.httpclient import HTTPClientError, HTTPRequest
    from tornado.websocket import websocket_connect

    headers = {"Authorization": f"Bearer {r['token']}"} if r.get("token") else {}
    req = HTTPRequest(r["url"], headers=headers, ssl_options=_ctx(r.get("cafile")))
    try:
        conn = await asyncio.wait_for(websocket_connect(req), 60)
    except HTTPClientError as e:
        return {"status": e.code}
    except Exception as e:
        return {"error": f"{type(e).__name__}: {e}"}
    try:
        msg = r.get("send")
        if msg is not None:
            await conn.write_message(json.dumps(msg))
            reply = await asyncio.wait_for(conn.read_message(), 60)
            return {"status": 101, "body": reply}
        return {"status": 101}
    finally:
        conn.close()


def main() -> None:
    out = {}
    for r in json.loads(sys.argv[1]):
        out[r["id"]] = asyncio.run(ws_request(r)) if r.get("ws") else http_request(r)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
