"""Sends requests with a real Python HTTP client and prints what the client saw, one JSON line each.

Usage: python3 clients.py urllib|requests < cases.json
cases.json: a list of {"name", "method", "url", "headers": {..}, "body": path of a file or null}.
Each output line: {"name", "status": int or null, "body": the answer text, "exception": null or
"Type: message" when the client raised instead of returning an answer}.
"""

import json
import sys


def with_urllib(case, body):
    import urllib.error
    import urllib.request

    req = urllib.request.Request(
        case["url"], data=body, method=case["method"], headers=case["headers"]
    )
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def with_requests(case, body):
    import requests

    r = requests.request(
        case["method"], case["url"], data=body, headers=case["headers"], timeout=60
    )
    return r.status_code, r.content


def main():
    client = {"urllib": with_urllib, "requests": with_requests}[sys.argv[1]]
    for case in json.load(sys.stdin):
        body = None
        if case.get("body"):
            with open(case["body"], "rb") as f:
                body = f.read()
        out = {"name": case["name"], "status": None, "body": "", "exception": None}
        try:
            status, text = client(case, body)
            out["status"] = status
            out["body"] = text.decode("utf-8", "replace")
        except Exception as e:  # what the client raised is the result
            reason = getattr(e, "reason", None)
            inner = reason if isinstance(reason, BaseException) else e
            out["exception"] = f"{type(inner).__name__}: {inner}"
        print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
