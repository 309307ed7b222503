#!/usr/bin/env python3
"""Help text, README and behaviour agree.

Runs every tool's --helpxml and --help and checks them against README.md and docs/guide.md:
  - every flag of a tool (its own file or tools/common/common_flags.cc) is documented in the README as
    `--name`, and every `--name` the README or the guide gives is a flag of some tool (or gflags');
  - the defaults the README gives in brackets in a tool's table ([30], [0.03], [rad]) are the
    tool's defaults, compared as numbers where both are numbers;
  - the ranges the README gives for a flag (2..100, [1, 10000]) are the ranges --help prints;
  - --help prints defaults as written (no 0.029999999999999999);
  - every tool's --help lists its exit codes, and each is one the README's exit code list explains;
  - the frames: what --tcp, --frame and --flange mean is said the same way in --help, the
    README's row, docs/compensation.md and the Python docstrings (python/src): a TCP is relative to
    the flange (never "in the last joint's frame"), --frame takes base, measurement and link:NAME,
    the flange defaults to tool0; docs/conventions.md defines each frame once.

Usage: help_docs_test.py <README.md> <docs/guide.md> <tool>...
"""
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET

GFLAGS_OWN = {"name",  # the README's `--name=value` of --flagfile
              "help", "helpfull", "helpshort", "helpxml", "helpon", "helpmatch", "helppackage",
              "version", "flagfile", "fromenv", "tryfromenv", "undefok", "v", "logtostderr"}

failures = []


def fail(message):
    failures.append(message)


def number(text):
    try:
        return float(text)
    except ValueError:
        return None


def tool_flags(tool):
    """name -> (type, default) of the tool's own flags and the shared ones."""
    name = os.path.basename(tool)
    xml = subprocess.run([tool, "--helpxml"], capture_output=True, text=True).stdout
    root = ET.fromstring(xml)
    flags = {}
    for flag in root.iter("flag"):
        source = flag.findtext("file")
        if name not in source and "common_flags.cc" not in source:
            continue
        flags[flag.findtext("name")] = (flag.findtext("type"), flag.findtext("default") or "")
    return flags, root.findtext("usage")


def help_ranges(tool):
    """name -> printed range, and the printed defaults, from --help."""
    text = subprocess.run([tool, "--help"], capture_output=True, text=True).stdout
    ranges, defaults = {}, {}
    current = None
    for line in text.splitlines():
        m = re.match(r"  --([a-z0-9_]+) \(", line)
        if m:
            current = m.group(1)
            continue
        m = re.match(r"\s+type: (\S+)\s+default: (.*?)(?:\s+range: (.*))?$", line)
        if m and current:
            defaults[current] = m.group(2)
            if m.group(3):
                ranges[current] = m.group(3)
    return ranges, defaults, text


def parse_range(text):
    """'[1, 10000]' / '(0, 90]' / '2..100' -> (lo, hi) as numbers, or None."""
    m = re.fullmatch(r"[\[(]\s*([-+0-9.e]+|-inf)\s*,\s*([-+0-9.e]+|inf)\s*[\])]", text.strip())
    if not m:
        m = re.fullmatch(r"([-+0-9.e]+)\s*\.\.\s*([-+0-9.e]+)", text.strip())
    if not m:
        return None
    lo, hi = (float(v) for v in m.groups())
    return lo, hi


def readme_sections(readme):
    """tool name -> list of table rows ([flags], description) of its README section."""
    sections, current = {}, None
    for line in readme.splitlines():
        m = re.match(r"#+ (lpoe_[a-z]+)\s*$", line)
        if m:
            current = m.group(1)
            sections.setdefault(current, [])
            continue
        if line.startswith("## "):
            current = None
        if current and line.startswith("|") and "`--" in line:
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            flags = re.findall(r"`--([a-z0-9_]+)", cells[0])
            sections[current].append((flags, " | ".join(cells[1:])))
    return sections


def exit_codes(usage):
    m = re.search(r"Exit codes:(.*)", usage, re.S)
    if not m:
        return None
    return set(int(c) for c in re.findall(r"(?<![\w.^/-])([0-9])(?= [a-z-])", m.group(1)))


# Frame meanings: flag -> phrases every description of it must contain, and phrases
# none may contain.
FRAME_MEANINGS = {
    "tcp": (["relative to the flange"], ["in the last joint's frame"]),
    "frame": (["base", "measurement", "link:NAME"], []),
    "flange": (["tool0", "flange frame"], []),
}


def help_entry(help_text, flag):
    """The --help paragraph of --flag (its description lines up to the type line)."""
    m = re.search(r"\n  --" + flag + r" \((.*?)\)\s+type:", help_text, re.S)
    return " ".join(m.group(1).split()) if m else None


def check_frame_meanings(root, readme, tools):
    def has_all(text, where, flag):
        wanted, banned = FRAME_MEANINGS[flag]
        for w in wanted:
            if w not in text:
                fail(f"{where}: --{flag} does not say '{w}'")
        for b in banned:
            if b in text:
                fail(f"{where}: --{flag} says '{b}'")

    for tool in tools:
        name = os.path.basename(tool)
        if name not in ("lpoe_compensate", "lpoe_predict"):
            continue
        text = subprocess.run([tool, "--help"], capture_output=True, text=True).stdout
        for flag in FRAME_MEANINGS:
            entry = help_entry(text, flag)
            if entry is not None:
                has_all(entry, f"{name} --help", flag)
    rows = readme_sections(readme)
    for name in ("lpoe_compensate",):
        for row_flags, description in rows.get(name, []):
            for flag in row_flags:
                if flag in FRAME_MEANINGS:
                    has_all(description, f"README {name} table", flag)
    # lpoe_predict's --frame is described in a paragraph.
    m = re.search(r"### lpoe_predict\n(.*?)\n### ", readme, re.S)
    if m:
        para = " ".join(m.group(1).split())
        i = para.find("`--frame`")
        if i < 0:
            fail("README lpoe_predict: --frame not described")
        else:
            has_all(para[i:i + 400], "README lpoe_predict", "frame")
    comp = open(os.path.join(root, "docs", "compensation.md"), encoding="utf-8").read()
    comp_flat = " ".join(comp.split())
    for flag in FRAME_MEANINGS:
        i = comp_flat.find(f"`--{flag}")
        if i < 0:
            fail(f"docs/compensation.md: --{flag} is not described")
        else:
            has_all(comp_flat[i:i + 600], "docs/compensation.md", flag)
    # The Python docstrings of lpoe.compensate and lpoe.compensate_program (in the C++ source).
    for source, flags in (("bind_analysis.cc", ("tcp", "frame", "flange")),
                          ("bind_program.cc", ("frame", "flange"))):
        path = os.path.join(root, "python", "src", source)
        text = " ".join(re.findall(r'"((?:[^"\\]|\\.)*)"', open(path, encoding="utf-8").read()))
        for flag in flags:
            # Some occurrence of `flag:` (or `frame`) describes it in full (error messages name
            # the keyword too); none says what it must not.
            starts = [m.start() for m in re.finditer(re.escape(f"{flag}:") + "|`" + flag + "`",
                                                     text)]
            wanted, banned = FRAME_MEANINGS[flag]
            if not any(all(w in text[i:i + 500] for w in wanted) for i in starts):
                fail(f"python/src/{source}: no docstring describes {flag} with "
                     f"{', '.join(repr(w) for w in wanted)}")
            for i in starts:
                for b in banned:
                    if b in text[i:i + 500]:
                        fail(f"python/src/{source}: {flag} is described as '{b}'")
    # docs/conventions.md: one table of frames, each frame in one row.
    conv = open(os.path.join(root, "docs", "conventions.md"), encoding="utf-8").read()
    m = re.search(r"\n## Frames\n(.*?)\n## ", conv, re.S)
    if not m:
        fail("docs/conventions.md: no '## Frames' section")
    else:
        names = re.findall(r"^\| \*\*([^*]+)\*\*", m.group(1), re.M)
        for frame in ("measurement frame", "base frame", "controller base", "last joint's frame",
                      "flange", "TCP"):
            count = names.count(frame)
            if count != 1:
                fail(f"docs/conventions.md: the frame '{frame}' is defined {count} times")


def main():
    readme_path, guide_path, tools = sys.argv[1], sys.argv[2], sys.argv[3:]
    readme = open(readme_path, encoding="utf-8").read()
    guide = open(guide_path, encoding="utf-8").read()
    sections = readme_sections(readme)
    general = re.search(r"\nExit codes: (.*?)\n\n", readme, re.S)
    readme_codes = set(int(c) for c in re.findall(r"(?:^|;)\s*([0-9])\s", general.group(1))) \
        if general else set()
    if not readme_codes:
        fail("README: no exit code list ('Exit codes: 0 success; 1 ...')")
    every_flag = set(GFLAGS_OWN)
    for tool in tools:
        name = os.path.basename(tool)
        flags, usage = tool_flags(tool)
        every_flag |= set(flags)
        ranges, printed_defaults, help_text = help_ranges(tool)
        # Exit codes listed in --help, each explained in the README.
        codes = exit_codes(usage or "")
        if not codes:
            fail(f"{name} --help lists no exit codes")
        else:
            for c in sorted(codes - readme_codes):
                fail(f"{name} --help lists exit code {c}, which the README's list does not explain")
        # Defaults printed as written.
        for flag, text in printed_defaults.items():
            if re.search(r"\d\.\d{12,}", text):
                fail(f"{name} --help prints --{flag}'s default as {text}")
        for flag in flags:
            if f"`--{flag}`" not in readme:
                fail(f"README: {name} --{flag} is not documented")
        # The README table of the tool: defaults in the last brackets, ranges anywhere.
        for row_flags, description in sections.get(name, []):
            brackets = re.findall(r"\[([^\[\]]*)\]", description)
            if brackets:
                items = [i.strip() for i in brackets[-1].split(",")]
                if len(items) == len(row_flags):
                    for flag, item in zip(row_flags, items):
                        if flag not in flags:
                            fail(f"README: {name} table names --{flag}, which {name} does not have")
                            continue
                        kind, default = flags[flag]
                        item = item.split(":")[0].strip()
                        if kind == "string":
                            # An empty default is described in words ([the limits], [tool 0]).
                            if item != default and default != "":
                                if number(item) is None or number(item) != number(default):
                                    fail(f"README: {name} --{flag} default [{item}], the tool's "
                                         f"is '{default}'")
                        elif kind != "bool" and number(item) is not None:
                            if number(default) is None or abs(number(item) - number(default)) > \
                                    1e-12 * max(1.0, abs(number(default))):
                                fail(f"README: {name} --{flag} default [{item}], the tool's is "
                                     f"{default}")
            for flag in row_flags:
                if flag not in ranges:
                    continue
                for stated in re.findall(r"(\d[0-9.e+-]*\s*\.\.\s*\d[0-9.e+-]*)", description):
                    if len(row_flags) == 1 and parse_range(stated) != parse_range(ranges[flag]):
                        fail(f"README: {name} --{flag} range {stated}, --help says {ranges[flag]}")
        # Every printed range is one the tool's help text prints for its flag (parseable).
        for flag, text in ranges.items():
            if parse_range(text) is None and "inf" not in text:
                fail(f"{name} --help: --{flag} range '{text}' is not [lo, hi]")
    for source, text in (("README", readme), ("docs/guide.md", guide)):
        for flag in sorted(set(re.findall(r"`--([a-z0-9_]+)", text))):
            if flag not in every_flag:
                fail(f"{source}: `--{flag}` is not a flag of any tool")
    check_frame_meanings(os.path.dirname(os.path.abspath(readme_path)), readme, tools)
    for f in failures:
        print(f)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
