"""Countries a racer may show beside their name: ISO 3166-1 alpha-2 codes and English short
names, read from ``countries.tsv`` (Debian's iso-codes ``iso_3166-1.json``, its common name
where it gives one: "Bolivia", not "Bolivia, Plurinational State of")."""

from __future__ import annotations

from pathlib import Path

COUNTRIES: dict[str, str] = dict(
    line.split("\t")
    for line in (Path(__file__).parent / "countries.tsv").read_text(encoding="utf-8").splitlines()
)


def country_name(code: str) -> str:
    """The country's English name, or "" for no country or an unknown code."""
    return COUNTRIES.get(code, "")
