"""Shared by the docs generators: keep project history out of user text.

Text the generators copy from the code (schema descriptions from doc comments, the
`contender` strings of bench/results.json) sometimes names the project's issues or a
date; user pages say what a thing is, not when or in which issue it came.
"""

from __future__ import annotations

import re

_RULES = [
    (re.compile(r"\b(built|made|rendered) before issue \d+"), r"\1 by earlier versions"),
    (re.compile(r"\((?:before|since|after) issue \d+\)"), "(earlier versions)"),
    (re.compile(r"\bbuilds before (?:this option|this|it)\b"), "earlier versions"),
    (re.compile(r"\s*\(issues? \d+[^()]*\)"), ""),
    (re.compile(r",?\s*\bissues? #?\d+(?:\s*[A-Z]\d+(?:/[A-Z]\d+)*)?:?"), ""),
    (re.compile(r"\s*\(?\b20\d\d-\d\d-\d\d\b\)?"), ""),
]

# What check.py refuses in a page a user reads.
FORBIDDEN = [
    (re.compile(r"\bissues? #?\d+", re.I), "an issue number"),
    (re.compile(r"\b20\d\d-\d\d-\d\d\b"), "a date"),
    (re.compile(r"\bload (?:average|avg)|\bload [≈~]?\s?\d", re.I), "a load average"),
    (re.compile(r"\bthis round\b|\bbuilds before (?:this|issue)\b", re.I), "project history"),
    (
        re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,12}\b"),
        "a commit hash",
    ),
]


def sanitize(text: str) -> str:
    for pattern, repl in _RULES:
        text = pattern.sub(repl, text)
    return text
