"""Check the daemon's web API against config/blueos/openapi.json with an
independent JSON Schema implementation (Python's jsonschema, draft
2020-12, which OpenAPI 3.1's schemas are): every documented GET answer,
one live event of the feed, and the 404's error body. Prints one JSON
object: what was checked; any mismatch is an exception (non-zero exit).

usage: web_openapi.py OPENAPI.json BASE_URL
"""
import json
import sys
import urllib.error
import urllib.request

from jsonschema import Draft202012Validator
from referencing import Registry, Resource
from referencing.jsonschema import DRAFT202012

spec_path, base = sys.argv[1], sys.argv[2].rstrip("/")
spec = json.load(open(spec_path))
assert spec["openapi"].startswith("3.1"), spec["openapi"]
URI = "urn:lightpose:openapi"
registry = Registry().with_resource(URI, Resource.from_contents(spec, default_specification=DRAFT202012))
for name, schema in spec["components"]["schemas"].items():
    Draft202012Validator.check_schema(schema)


def validator(ref):
    return Draft202012Validator({"$ref": f"{URI}{ref}"}, registry=registry)


def schema_of(path, code):
    resp = spec["paths"][path]["get"]["responses"][str(code)]
    return resp["content"]["application/json"]["schema"]["$ref"]


def get(path):
    try:
        with urllib.request.urlopen(base + path, timeout=10) as r:
            return r.status, r.headers.get("Content-Type"), r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.headers.get("Content-Type"), e.read()


checked = []
for path in ["/register_service", "/v1/status", "/v1/pose"]:
    code, ctype, body = get(path)
    assert code == 200, (path, code, body[:200])
    assert ctype == "application/json", (path, ctype)
    doc = json.loads(body)
    errors = sorted(validator(schema_of(path, 200)).iter_errors(doc), key=str)
    assert not errors, (path, [e.message for e in errors[:5]])
    checked.append(path)

code, ctype, body = get("/no/such/page")
assert code == 404, code
errs = list(validator("#/components/schemas/Error").iter_errors(json.loads(body)))
assert not errs, errs
checked.append("404")

# One live event off the feed, as a browser's EventSource reads it.
with urllib.request.urlopen(base + "/v1/events", timeout=10) as r:
    assert r.headers.get("Content-Type") == "text/event-stream", r.headers
    name = None
    for raw in r:
        line = raw.decode().rstrip("\n")
        if line.startswith("event: "):
            name = line[7:]
        elif line.startswith("data: ") and name == "live":
            ev = json.loads(line[6:])
            errs = list(validator("#/components/schemas/LiveEvent").iter_errors(ev))
            assert not errs, [e.message for e in errs[:5]]
            checked.append("live")
            break

print(json.dumps({"checked": checked}))
