"""MkDocs hooks of the documentation site (``hooks:`` in ``mkdocs.yml``).

- ``reference/http.md`` is generated at build time from the service's OpenAPI document
  (``service.main.create_app().openapi()``, embedded mode, no warm-up): every route with its method,
  path, summary, parameters, request body and answers.
- MathJax is served from the site itself: the static MathJax 2.7 of the ``jupyter-server-mathjax``
  package is copied to ``assets/mathjax/`` and loaded only by pages that hold math (``arithmatex``
  spans in Markdown pages; the notebooks' own MathJax tag is pointed at the local copy). Notebook pages
  rendered by mkdocs-jupyter also lose nbconvert's Mermaid loader, which would import from a CDN.
  The built site requests nothing from elsewhere.
"""

from __future__ import annotations

import json
import logging
import os
import posixpath
import re
import shutil
import sys
from pathlib import Path
from typing import Any

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File, Files
from mkdocs.structure.pages import Page

log = logging.getLogger("mkdocs.hooks.nonholonomic_docs")

ROOT = Path(__file__).resolve().parents[2]
HTTP_PAGE = "reference/http.md"
MATHJAX_DIR = "assets/mathjax"
HTTP_METHODS = ("get", "post", "put", "patch", "delete", "head", "options")

#: The combined configuration shipped (TeX input with the AMS extensions, HTML-CSS output: the package
#: has no separate jax files).
MATHJAX_COMBINED = "TeX-AMS-MML_HTMLorMML-full"
#: MathJax 2 configuration for the ``arithmatex`` (generic) output of pymdownx: only its spans and divs
#: are typeset, so a ``$`` in the prose or the code is never taken for math.
ARITHMATEX_CONFIG = {
    "tex2jax": {"inlineMath": [["\\(", "\\)"]], "displayMath": [["\\[", "\\]"]], "processEscapes": True,
                "processEnvironments": False, "ignoreClass": ".*|", "processClass": "arithmatex"},
    "HTML-CSS": {"availableFonts": [], "preferredFont": None, "webFont": "STIX-Web", "imageFont": None},
    "showMathMenu": False, "messageStyle": "none",
}
#: Added to a notebook page beside nbconvert's own MathJax configuration: the fonts that are shipped.
NOTEBOOK_FONT_CONFIG = ('<script type="text/x-mathjax-config">MathJax.Hub.Config({"HTML-CSS": {"availableFonts": [], '
                        '"preferredFont": null, "webFont": "STIX-Web", "imageFont": null}});</script>')

#: nbconvert's MathJax tag: its CDN URL, or empty when mkdocs-jupyter's ``custom_mathjax_url`` is not set.
NOTEBOOK_MATHJAX = re.compile(r'<script src="(?:https?://[^"]*mathjax[^"]*)?">\s*</script>', re.IGNORECASE)
MERMAID_LOADER = re.compile(r'<script type="module">(?:(?!</script>).)*?mermaid(?:(?!</script>).)*?</script>',
                            re.DOTALL)


# --------------------------------------------------------------------------------------------------
# The HTTP API page from the OpenAPI document


def openapi_document() -> dict[str, Any]:
    """The service's OpenAPI document, built as ``tests/api/test_openapi.py`` builds it (embedded mode)."""
    os.environ.pop("REDIS_URL", None)
    os.environ.pop("NONHOLONOMIC_REDIS_URL", None)
    os.environ.setdefault("NONHOLONOMIC_WARM_UP", "false")
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    try:
        from schemas.settings import get_settings
        from service.main import create_app
    except ImportError as exc:  # the docs are built from the checkout with the project installed
        raise PluginError(f"cannot import the service to read its OpenAPI document: {exc}") from exc
    cache_clear = getattr(get_settings, "cache_clear", None)
    if cache_clear is not None:
        cache_clear()  # settings read with the environment above
    return create_app().openapi()


def _cell(text: Any) -> str:
    """Text made safe for one Markdown table cell."""
    return _prose(text).replace("|", "\\|")


def _prose(text: Any) -> str:
    """Text on one line, with nothing Markdown would take for a link or a tag."""
    flat = " ".join(str(text or "").split())
    return (flat.replace("<", "&lt;").replace(">", "&gt;")
            .replace("[", "\\[").replace("]", "\\]"))


def _first_paragraph(text: str | None) -> str:
    return (text or "").strip().split("\n\n")[0]


def _schema_name(schema: dict[str, Any] | None) -> str:
    """A schema's name (``$ref``), or a short description of an inline one."""
    if not schema:
        return ""
    if "$ref" in schema:
        return schema["$ref"].rsplit("/", 1)[-1]
    for combo in ("anyOf", "oneOf", "allOf"):
        if combo in schema:
            return " or ".join(filter(None, (_schema_name(s) for s in schema[combo])))
    kind = schema.get("type", "")
    if kind == "array":
        return f"array of {_schema_name(schema.get('items')) or 'any'}"
    if "enum" in schema:
        return " \\| ".join(f"`{v}`" for v in schema["enum"])
    if "const" in schema:
        return f"`{schema['const']}`"
    return str(kind) if kind else "object"


def _anchor(name: str) -> str:
    return "schema-" + re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-")


def _schema_link(schema: dict[str, Any] | None, components: dict[str, Any]) -> str:
    name = _schema_name(schema)
    if schema and "$ref" in schema and name in components:
        return f"[`{name}`](#{_anchor(name)})"
    return name


def http_api_markdown(doc: dict[str, Any]) -> str:
    """The reference page: one section per route, then the request and answer schemas."""
    info = doc.get("info", {})
    components = doc.get("components", {}).get("schemas", {})
    operations = [(path, method, op) for path, item in doc.get("paths", {}).items()
                  for method, op in item.items() if method in HTTP_METHODS]
    lines = [
        "# HTTP API reference",
        "",
        f"Generated when the site is built from the service's own OpenAPI document "
        f"({info.get('title', '')} {info.get('version', '')}, OpenAPI {doc.get('openapi', '')}): "
        f"{len(operations)} operations. A running service serves the same document at `/openapi.json` and "
        "browses it at `/docs`; [the API guide](../api.md) explains the routes with examples.",
        "",
        "| method | path | summary |",
        "|---|---|---|",
    ]
    for path, method, op in operations:
        lines.append(f"| `{method.upper()}` | [`{path}`](#{op.get('operationId', '')}) | {_cell(op.get('summary'))} |")
    lines.append("")
    tags: dict[str, list[tuple[str, str, dict[str, Any]]]] = {}
    for path, method, op in operations:
        tags.setdefault((op.get("tags") or ["other"])[0], []).append((path, method, op))
    for tag, ops in tags.items():
        lines += [f"## {tag}", ""]
        for path, method, op in ops:
            lines += _operation(path, method, op, components)
    if components:
        lines += ["## Schemas", "",
                  "The request bodies and answers named above (fields with their type, whether required, and "
                  "their description).", ""]
        for name in sorted(components):
            lines += _schema(name, components[name], components)
    return "\n".join(lines) + "\n"


def _operation(path: str, method: str, op: dict[str, Any], components: dict[str, Any]) -> list[str]:
    op_id = op.get("operationId", "")
    out = [f"### `{method.upper()} {path}` {{ #{op_id} }}" if op_id else f"### `{method.upper()} {path}`", ""]
    if op.get("summary"):
        out += [f"**{op['summary'].strip()}**", ""]
    description = _first_paragraph(op.get("description"))
    if description:
        out += [_prose(description), ""]
    if op_id:
        out += [f"Operation id: `{op_id}`.", ""]
    params = op.get("parameters") or []
    if params:
        out += ["| parameter | in | required | type | description |", "|---|---|---|---|---|"]
        for p in params:
            out.append(f"| `{p.get('name')}` | {p.get('in')} | {'yes' if p.get('required') else 'no'} | "
                       f"{_cell(_schema_name(p.get('schema')))} | {_cell(p.get('description'))} |")
        out.append("")
    body = op.get("requestBody")
    if body:
        parts = [f"{_schema_link(media.get('schema'), components)} as `{kind}`"
                 for kind, media in body.get("content", {}).items()]
        out += [f"Request body{' (required)' if body.get('required') else ''}: {', '.join(parts)}.", ""]
    responses = op.get("responses") or {}
    if responses:
        out += ["| status | media types | body | description |", "|---|---|---|---|"]
        for status in sorted(responses, key=str):
            answer = responses[status]
            content = answer.get("content") or {}
            kinds = ", ".join(f"`{k}`" for k in content) or "(none)"
            bodies = ", ".join(filter(None, (_schema_link(m.get("schema"), components) for m in content.values())))
            out.append(f"| {status} | {kinds} | {bodies} | {_cell(answer.get('description'))} |")
        out.append("")
    return out


def _schema(name: str, schema: dict[str, Any], components: dict[str, Any]) -> list[str]:
    out = [f"### `{name}` {{ #{_anchor(name)} }}", ""]
    description = _first_paragraph(schema.get("description"))
    if description:
        out += [_prose(description), ""]
    props = schema.get("properties") or {}
    required = set(schema.get("required") or ())
    if props:
        out += ["| field | type | required | description |", "|---|---|---|---|"]
        for field, sub in props.items():
            out.append(f"| `{field}` | "
                       f"{_cell(_schema_link(sub, components)) if '$ref' not in sub else _schema_link(sub, components)}"
                       f" | {'yes' if field in required else 'no'} | "
                       f"{_cell(sub.get('description') or sub.get('title'))} |")
        out.append("")
    elif "enum" in schema:
        out += ["One of " + ", ".join(f"`{json.dumps(v)}`" for v in schema["enum"]) + ".", ""]
    return out


# --------------------------------------------------------------------------------------------------
# Hooks


def on_files(files: Files, config: MkDocsConfig) -> Files:
    """Add the generated HTTP reference page."""
    files.append(File.generated(config, HTTP_PAGE, content=http_api_markdown(openapi_document())))
    return files


def _mathjax_source() -> Path:
    try:
        import jupyter_server_mathjax
    except ImportError as exc:
        raise PluginError("MathJax is served from the site itself: install jupyter-server-mathjax "
                          "(pip install 'jupyter-server-mathjax>=0.2.6'), the MathJax 2.7 it ships is copied "
                          "into the site") from exc
    source = Path(jupyter_server_mathjax.__file__).parent / "static"
    if not (source / "MathJax.js").is_file():
        raise PluginError(f"no MathJax.js in {source}")
    return source


def on_config(config: MkDocsConfig) -> MkDocsConfig:
    """Fail early without MathJax. (Every notebook must be in the nav: the strict build's
    ``omitted_files`` check refuses one that is not.)"""
    _mathjax_source()
    return config


def _relative(page: Page, target: str) -> str:
    """``target`` (a path in the site) relative to the page's directory."""
    here = posixpath.dirname(page.url.rstrip("/") + "/x") if page.url else ""
    return posixpath.relpath(target, here or ".")


def on_post_page(output: str, page: Page, config: MkDocsConfig) -> str:
    """Load the local MathJax on pages with math; rid notebook pages of nbconvert's CDN loaders."""
    script = _relative(page, f"{MATHJAX_DIR}/MathJax.js")
    notebook = page.file.src_uri.endswith(".ipynb")
    if notebook:
        output = MERMAID_LOADER.sub("", output)
        output, found = NOTEBOOK_MATHJAX.subn(
            f'{NOTEBOOK_FONT_CONFIG}<script src="{script}?config={MATHJAX_COMBINED},Safe"></script>',
            output, count=1)
        output = NOTEBOOK_MATHJAX.sub("", output)
    elif 'class="arithmatex"' in output:
        tag = (f"<script>window.MathJax = {json.dumps(ARITHMATEX_CONFIG)};</script>\n"
               f'<script src="{script}?config={MATHJAX_COMBINED}"></script>\n')
        output = output.replace("</body>", tag + "</body>", 1)
    return output


def on_post_build(config: MkDocsConfig) -> None:
    """Copy MathJax (its scripts and STIX-Web fonts) into the site."""
    source = _mathjax_source()
    target = Path(config["site_dir"]) / MATHJAX_DIR
    if target.exists():
        shutil.rmtree(target)
    shutil.copytree(source, target, ignore=shutil.ignore_patterns("*.md", "*.txt"))
    log.info("MathJax copied from %s to %s", source, target)
