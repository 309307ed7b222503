#!/usr/bin/env python3
"""Strict well-formedness check of an HTML file (used by report_html_test).

Every non-void element is closed in order, void elements (and SVG elements written as <x/>) need
no end tag, entity references are known, attributes are not repeated, there is exactly one <html>
root and no <script>. Prints the first problem with its line and exits 1; exits 0 when the file is
well-formed.
"""
import html.entities
import html.parser
import sys

VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source",
        "track", "wbr"}


class Checker(html.parser.HTMLParser):
    def __init__(self):
        super().__init__(convert_charrefs=False)
        self.stack = []
        self.roots = 0
        self.errors = []

    def error_at(self, what):
        self.errors.append("line %d: %s" % (self.getpos()[0], what))

    def check_attrs(self, tag, attrs):
        names = [a for a, _ in attrs]
        if len(names) != len(set(names)):
            self.error_at("<%s> repeats an attribute" % tag)

    def handle_starttag(self, tag, attrs):
        self.check_attrs(tag, attrs)
        if tag == "script":
            self.error_at("<script> found: the report must read without JavaScript")
        if tag == "html":
            self.roots += 1
        if not self.stack and tag != "html":
            self.error_at("<%s> outside <html>" % tag)
        if tag not in VOID:
            self.stack.append((tag, self.getpos()[0]))

    def handle_startendtag(self, tag, attrs):
        self.check_attrs(tag, attrs)
        if not self.stack:
            self.error_at("<%s/> outside <html>" % tag)

    def handle_endtag(self, tag):
        if tag in VOID:
            self.error_at("end tag of the void element <%s>" % tag)
            return
        if not self.stack:
            self.error_at("</%s> without an open element" % tag)
            return
        top, line = self.stack.pop()
        if top != tag:
            self.error_at("</%s> closes <%s> opened on line %d" % (tag, top, line))

    def handle_entityref(self, name):
        if name not in html.entities.name2codepoint:
            self.error_at("unknown entity &%s;" % name)

    def handle_charref(self, name):
        try:
            int(name[1:], 16) if name[:1] in "xX" else int(name)
        except ValueError:
            self.error_at("bad character reference &#%s;" % name)


def main():
    with open(sys.argv[1], encoding="utf-8") as f:
        text = f.read()
    if not text.lstrip().lower().startswith("<!doctype html>"):
        print("missing <!DOCTYPE html>")
        return 1
    checker = Checker()
    checker.feed(text)
    checker.close()
    for tag, line in checker.stack:
        checker.errors.append("<%s> opened on line %d is never closed" % (tag, line))
    if checker.roots != 1:
        checker.errors.append("%d <html> elements" % checker.roots)
    if checker.errors:
        print(checker.errors[0])
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
