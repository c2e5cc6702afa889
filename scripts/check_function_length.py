#!/usr/bin/env python3
"""Lists C++ functions longer than a limit (STYLE.md: short functions with one job).

  scripts/check_function_length.py [DIR_OR_FILE ...] [--max-lines N] [--top K]

Scans the .cc and .h files under the given folders (default: pipeline synth eval
apps core, relative to the repository root) and prints every function whose body
spans more than N lines (default 150) as

  path:line: NAME is L lines (limit N)

where `line` is the line of the function's name and L counts the lines from
there to the closing brace, both included. Exits 1 if any function is too long,
0 otherwise. With --top K it prints the K longest functions instead (longest
first), whatever their length; the exit status still reflects the limit.

What counts as a function: a definition whose head (the code since the previous
`;`, `{` or `}` of the enclosing namespace or class) ends in a parameter list
followed only by qualifiers (const, noexcept, override, final, &, a trailing
return type, a requires clause) or by a constructor's initialiser list.
Member functions defined in class bodies count; class, struct, union, enum and
namespace bodies and brace initialisers do not. Lambdas count towards the
function they are written in (a lambda at namespace scope is a function of its
own). Braces in comments, string literals (raw ones too), character literals
and preprocessor lines are ignored. Python 3 standard library only.
"""
import argparse
import os
import re
import sys

DEFAULT_DIRS = ["pipeline", "synth", "eval", "apps", "core"]
EXTENSIONS = (".cc", ".h")

# Words that may follow a function's parameter list before its body.
TAIL_WORDS = {"const", "volatile", "noexcept", "override", "final", "mutable", "constexpr", "consteval", "throw",
              "try"}
CONTAINER_WORDS = re.compile(r"\b(class|struct|union|enum|namespace|extern)\b")
NAME_RE = re.compile(
    r"((?:[A-Za-z_]\w*\s*(?:<[^;{}()]*>)?\s*::\s*)*"
    r"(?:operator\s*(?:\(\s*\)|\[\s*\]|new\b|delete\b|[^\w\s(]+|[A-Za-z_][\w:\s<>*&]*?)|~?[A-Za-z_]\w*))\s*$")


def strip_code(text):
    """Returns `text` with comments, string and character literals and
    preprocessor lines replaced by spaces (newlines kept, so offsets and line
    numbers are unchanged). Literals keep their quotes."""
    out = list(text)
    n = len(text)
    i = 0
    line_start = True  # only whitespace so far on this line

    def blank(a, b):
        for k in range(a, b):
            if out[k] != "\n":
                out[k] = " "

    while i < n:
        ch = text[i]
        if ch == "\n":
            line_start = True
            i += 1
            continue
        if ch in " \t\r\f\v":
            i += 1
            continue
        if line_start and ch == "#":
            # A preprocessor directive, with its continuation lines and comments.
            j = i
            while j < n and text[j] != "\n":
                if text[j] == "\\" and j + 1 < n and text[j + 1] == "\n":
                    j += 2
                    continue
                if text.startswith("/*", j):
                    end = text.find("*/", j + 2)
                    j = n if end < 0 else end + 2
                    continue
                if text.startswith("//", j):
                    while j < n and text[j] != "\n":
                        j += 1
                    break
                j += 1
            blank(i, j)
            i = j
            continue
        line_start = False
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            blank(i, j)
            i = j
            continue
        if text.startswith("/*", i):
            end = text.find("*/", i + 2)
            j = n if end < 0 else end + 2
            blank(i, j)
            i = j
            continue
        raw = re.match(r'(?:u8|u|U|L)?R"([^()\\\s]{0,16})\(', text[i:i + 24])
        if raw and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            close = ")" + raw.group(1) + '"'
            start = i + raw.end()
            end = text.find(close, start)
            j = n if end < 0 else end + len(close)
            blank(start, j - 1 if end >= 0 else j)
            i = j
            continue
        if ch.isdigit() or (ch == "." and i + 1 < n and text[i + 1].isdigit()):
            if i > 0 and (text[i - 1].isalnum() or text[i - 1] == "_"):
                i += 1  # a digit inside an identifier
                continue
            # A pp-number: digit separators (1'000) are not character literals.
            j = i + 1
            while j < n:
                c = text[j]
                if c.isalnum() or c in "._":
                    j += 1
                elif c == "'" and j + 1 < n and (text[j + 1].isalnum() or text[j + 1] == "_"):
                    j += 2
                elif c in "+-" and text[j - 1] in "eEpP":
                    j += 1
                else:
                    break
            i = j
            continue
        if ch == '"' or ch == "'":
            j = i + 1
            while j < n and text[j] != ch and text[j] != "\n":
                j += 2 if text[j] == "\\" else 1
            blank(i + 1, min(j, n))
            i = j + 1
            continue
        if ch.isalpha() or ch == "_":
            j = i + 1
            while j < n and (text[j].isalnum() or text[j] == "_"):
                j += 1
            i = j
            continue
        i += 1
    return "".join(out)


def top_level_groups(head):
    """The (start, end) spans of the parenthesised groups of `head` at depth 0
    (end exclusive), and whether a parenthesis stays open."""
    groups = []
    depth = 0
    start = 0
    for k, c in enumerate(head):
        if c == "(":
            if depth == 0:
                start = k
            depth += 1
        elif c == ")":
            depth -= 1
            if depth == 0:
                groups.append((start, k + 1))
            if depth < 0:
                depth = 0
    return groups, depth > 0


def is_function_tail(tail):
    """Whether the code after a parameter list can precede a function body."""
    tail = tail.strip()
    if tail.startswith(":") and not tail.startswith("::"):
        return True  # a constructor's initialiser list
    k = 0
    while k < len(tail):
        if tail[k].isspace() or tail[k] == "&":
            k += 1
            continue
        if tail.startswith("->", k) or re.match(r"requires\b", tail[k:]):
            return True  # a trailing return type or a constraint: anything may follow
        word = re.match(r"[A-Za-z_]\w*", tail[k:])
        if not word or word.group(0) not in TAIL_WORDS:
            return False
        k += word.end()
        if word.group(0) in ("noexcept", "throw"):
            rest = tail[k:]
            m = re.match(r"\s*\(", rest)
            if m:
                depth = 0
                for j in range(k + m.end() - 1, len(tail)):
                    depth += {"(": 1, ")": -1}.get(tail[j], 0)
                    if depth == 0:
                        k = j + 1
                        break
                else:
                    return False
    return True


def function_name(head, group_start):
    """(name, offset in head of the name) for the parameter list at `group_start`."""
    before = head[:group_start]
    if before.rstrip().endswith("]"):
        # A lambda: name it after the variable it initialises, if any.
        var = re.search(r"([A-Za-z_]\w*)\s*(?:=|\{|\()[^=]*$", before)
        pos = before.rfind("[")
        return ("lambda" if not var else var.group(1) + " (lambda)"), max(pos, 0)
    m = NAME_RE.search(before)
    if not m:
        stripped = before.rstrip()
        return "?", len(stripped) - len(stripped.lstrip()) if stripped else 0
    name = re.sub(r"\s+", "", m.group(1)) if "operator" not in m.group(1) else " ".join(m.group(1).split())
    bare = name.split("::")[-1]
    if re.fullmatch(r"[A-Z][A-Z0-9_]*", bare):
        # A macro such as TEST(Suite, Name): keep its arguments.
        group_end = head.find(")", group_start)
        name += re.sub(r"\s+", " ", head[group_start:group_end + 1])
    return name, m.start(1)


def classify(head):
    """'function' (with name and offset), 'container' or 'init' for a `{` at
    namespace or class scope whose head is `head`."""
    groups, unclosed = top_level_groups(head)
    if unclosed:
        return ("init",)  # a brace inside a call's arguments
    for start, end in groups:
        if not is_function_tail(head[end:]):
            continue
        before = head[:start].rstrip()
        last = re.search(r"([A-Za-z_]\w*)$", before)
        if last and last.group(1) in ("noexcept", "throw", "decltype", "alignas", "requires", "sizeof"):
            continue
        if not before:
            continue
        name, pos = function_name(head, start)
        return ("function", name, pos)
    if re.search(r"\]\s*$", head) and "=" in head or re.search(r"[=(,]\s*\[[^\]]*\]\s*$", head):
        name, pos = function_name(head + "()", len(head))
        return ("function", name, pos)  # a lambda without a parameter list
    if CONTAINER_WORDS.search(head):
        return ("container",)
    if "=" in head or re.search(r"[\w>\]]\s*$", head) and head.strip():
        return ("init",)
    return ("container",)


def find_functions(text):
    """[(name, first line, last line)] of the function definitions in C++ `text`."""
    code = strip_code(text)
    line_of = []
    line = 1
    for c in code:
        line_of.append(line)
        if c == "\n":
            line += 1
    functions = []
    # Scopes: (kind, data); kinds 'container', 'init', 'function', 'inner', 'member-init'.
    stack = []
    head_start = 0
    in_function = 0  # depth of braces inside a function body (0 = outside)
    for k, c in enumerate(code):
        if c not in "{};":
            continue
        if in_function:
            if c == "{":
                in_function += 1
            elif c == "}":
                in_function -= 1
                if in_function == 0:
                    name, first = stack.pop()[1]
                    functions.append((name, line_of[first], line_of[k]))
                    head_start = k + 1
            continue
        kind = stack[-1][0] if stack else "container"
        if c == ";":
            if kind not in ("init", "member-init"):
                head_start = k + 1
            continue
        if c == "}":
            popped = stack.pop()[0] if stack else "container"
            if popped == "container":
                head_start = k + 1
            # else a brace initialiser (a default argument's, a member's in a
            # constructor's list, a variable's): the head goes on.
            continue
        # c == "{"
        if kind in ("init", "member-init"):
            last = max(code.rfind("{", 0, k), code.rfind("}", 0, k), code.rfind(";", 0, k))
            head = code[last + 1:k]
            if re.search(r"\)[^()]*$", head) or re.search(r"\]\s*$", head):
                cls = classify(head)
                if cls[0] == "function" and ("lambda" in cls[1]):
                    stack.append(("function", (cls[1], last + 1 + cls[2])))
                    in_function = 1
                    continue
            stack.append(("init", None))
            continue
        head = code[head_start:k]
        groups, unclosed = top_level_groups(head)
        ctor = next((g for g in groups if head[g[1]:].lstrip().startswith(":")
                     and not head[g[1]:].lstrip().startswith("::")), None)
        if ctor is not None and not unclosed and re.search(r"[\w>]\s*$", head) and \
                is_function_tail(head[ctor[1]:]):
            stack.append(("member-init", None))  # a brace initialiser in a constructor's list
            continue
        cls = classify(head)
        if cls[0] == "function":
            stack.append(("function", (cls[1], head_start + cls[2])))
            in_function = 1
        else:
            stack.append((cls[0], None))
            if cls[0] == "container":
                head_start = k + 1
    return functions


def source_files(paths):
    for p in paths:
        if os.path.isfile(p):
            yield p
            continue
        for root, dirs, files in os.walk(p):
            dirs[:] = sorted(d for d in dirs if not d.startswith(".") and not d.startswith("build"))
            for f in sorted(files):
                if f.endswith(EXTENSIONS):
                    yield os.path.join(root, f)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("paths", nargs="*", help="folders or files (default: %s)" % " ".join(DEFAULT_DIRS))
    parser.add_argument("--max-lines", type=int, default=150, help="longest allowed function, lines (default 150)")
    parser.add_argument("--top", type=int, default=0, metavar="K", help="print the K longest functions instead")
    args = parser.parse_args(argv)
    if args.max_lines < 1:
        parser.error("--max-lines must be >= 1")
    if args.top < 0:
        parser.error("--top must be >= 0")
    paths = args.paths
    if not paths:
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        paths = [os.path.relpath(os.path.join(root, d)) for d in DEFAULT_DIRS if os.path.isdir(os.path.join(root, d))]
    for p in paths:
        if not os.path.exists(p):
            parser.error("%s: no such file or folder" % p)
    found = []  # (lines, path, line, name)
    for path in source_files(paths):
        with open(path, encoding="utf-8", errors="replace") as f:
            text = f.read()
        for name, first, last in find_functions(text):
            found.append((last - first + 1, path, first, name))
    too_long = [f for f in found if f[0] > args.max_lines]
    if args.top:
        shown = sorted(found, key=lambda f: (-f[0], f[1], f[2]))[:args.top]
    else:
        shown = sorted(too_long, key=lambda f: (f[1], f[2]))
    for lines, path, line, name in shown:
        print("%s:%d: %s is %d lines (limit %d)" % (path, line, name, lines, args.max_lines))
    return 1 if too_long else 0


if __name__ == "__main__":
    sys.exit(main())
