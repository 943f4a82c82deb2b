"""One line of attribution for a character (``Character.credits``), from whichever meta its file has.

The glTF asset and the two VRM metas name the same things differently; each
reader picks its fields and this joins them the same way: "title by author,
note, licence".
"""

from __future__ import annotations


def credit_line(title: str, author: str, licence: str, extra: str) -> str:
    """"<title> by <author>, <extra>, <licence>", leaving out what is empty; an extra note starting with
    "Adapted" or "Converted" is lower-cased to read on after the comma."""
    parts = []
    if title and author:
        parts.append(f"{title} by {author}")
    elif title or author:
        parts.append(title or f"by {author}")
    if extra:
        parts.append(extra[0].lower() + extra[1:] if extra[:1].isupper() and extra.split()[0] in
                     ("Adapted", "Converted") else extra)
    if licence:
        parts.append(licence)
    return ", ".join(parts)


def text(meta: dict, key: str) -> str:
    """``meta[key]`` stripped when it is a string, else ""."""
    v = meta.get(key)
    return v.strip() if isinstance(v, str) else ""
