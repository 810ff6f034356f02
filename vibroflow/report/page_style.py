"""The style that the study's and the sweep's report pages share: the page's frame, headings,
navigation, figures and verdict colours; each page adds the style of its own tables."""
from __future__ import annotations


def page_css(max_width_px: int) -> str:
    """The shared CSS of a report page max_width_px (px) wide at most."""
    return f"""
body {{ font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: {max_width_px}px;
       color: #222; padding: 0 1em; }}
h1 {{ font-size: 1.6em; margin-bottom: 0.2em; }}
h2 {{ border-bottom: 1px solid #ccc; padding-bottom: 0.2em; margin-top: 1.6em; }}
nav a {{ margin-right: 0.9em; }}
img {{ max-width: 100%; height: auto; display: block; margin: 0.5em 0; }}
.note {{ color: #8a5a00; }}
.ok {{ color: #1a7f37; }} .bad {{ color: #b42318; }}
"""
