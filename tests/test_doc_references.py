"""Every reference to a section of the docs (docs/model.md "Gate switches") in the code, the studies
and the docs names a heading or a bold paragraph title that exists: two docstrings cited sections
that never were ("Friction law", "ESDIRK4")."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = re.compile(r'docs/(\w+)\.md[,:]?\s+\(?"([^"]{3,80})"')


def titles(text: str) -> list[str]:
    """The headings and bold paragraph titles of a Markdown text, lower case, without backticks."""
    found = [line.lstrip("#").strip() for line in text.splitlines() if line.startswith("#")]
    found += re.findall(r"\*\*([^*]+)\*\*", text)
    return [t.replace("`", "").lower() for t in found]


def joined(path: Path) -> str:
    """The file's text with its lines joined (a reference may wrap), comment marks and docstring
    indents dropped."""
    return " ".join(line.strip().lstrip("#").strip() for line in path.read_text().splitlines())


def test_every_section_a_text_cites_exists():
    sources = [*ROOT.glob("warpfric/*.py"), *ROOT.glob("kernels/*.py"), *ROOT.glob("studies/*.py"),
               *ROOT.glob("docs/*.md"), ROOT / "README.md", ROOT / "studies" / "README.md"]
    docs = {path.stem: titles(path.read_text()) for path in ROOT.glob("docs/*.md")}
    cited, missing = 0, []
    for source in sources:
        for doc, section in REFERENCE.findall(joined(source)):
            cited += 1
            wanted = section.replace("`", "").lower()
            if not any(wanted in title for title in docs.get(doc, [])):
                missing.append(f"{source.relative_to(ROOT)}: docs/{doc}.md \"{section}\"")
    assert cited > 100  # the pattern still finds the references
    assert missing == []
