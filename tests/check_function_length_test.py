#!/usr/bin/python3
"""Tests scripts/check_function_length.py on small C++ fixtures written here.

    python3 tests/check_function_length_test.py        (exit code 0 = pass)

Each fixture's functions have lengths that can be counted by eye: a function's
length runs from the line of its name to its closing brace, both included.
"""
import io
import os
import subprocess
import sys
import tempfile
import textwrap
import unittest
from contextlib import redirect_stdout

HERE = os.path.dirname(os.path.abspath(__file__))
SCRIPT = os.path.join(HERE, "..", "scripts", "check_function_length.py")

sys.dont_write_bytecode = True  # no __pycache__ in scripts/
sys.path.insert(0, os.path.dirname(SCRIPT))
import check_function_length as cfl  # noqa: E402


def functions(code):
    """{name: length} of the functions in `code`."""
    return {name: last - first + 1 for name, first, last in cfl.find_functions(textwrap.dedent(code))}


class FindFunctions(unittest.TestCase):
    def test_three_line_function(self):
        self.assertEqual(functions("""\
            int Three() {
              return 3;
            }
            """), {"Three": 3})

    def test_one_line_function_and_declarations(self):
        self.assertEqual(functions("""\
            int Declared(int x);
            int One() { return 1; }
            extern int counter;
            """), {"One": 1})

    def test_lambda_and_string_braces_count_towards_the_function(self):
        found = functions("""\
            #include <string>
            #define OPEN {
            std::string Outer(int n) {
              auto f = [&](int k) {
                return k + n;  // } a brace in a comment
              };
              /* { */
              const char c = '{';
              std::string s = "}}}{";
              std::string r = R"x(}")x";
              int big = 1'000'000;
              if (f(1) > 0) { s += c; }
              return s + r + std::to_string(big);
            }
            int After() { return 0; }
            """)
        self.assertEqual(found, {"Outer": 12, "After": 1})

    def test_classes_namespaces_enums_are_not_functions(self):
        found = functions("""\
            namespace outer {
            namespace {
            enum class Colour : int { kRed, kGreen };
            struct Point {
              int x = 0;
              int y{0};
              int Sum() const {
                return x + y;
              }
            };
            const int kTable[] = {1, 2, 3};
            }  // namespace
            class Widget : public Base<int(int)> {
             public:
              Widget(int a) : a_(a), b_{a, {a}} {
                Init();
              }
              ~Widget() override { Done(); }
              bool operator==(const Widget& o) const noexcept(true) { return a_ == o.a_; }
              auto Size() const -> int {
                return 1;
              }
             private:
              int a_;
            };
            int Widget::Twice(Options o = {}) const {
              return 2 * a_;
            }
            }  // namespace outer
            """)
        self.assertEqual(found, {"Sum": 3, "Widget": 3, "~Widget": 1, "operator==": 1,
                                 "Size": 3, "Widget::Twice": 3})

    def test_lambda_in_a_namespace_initialiser_is_its_own_function(self):
        found = functions("""\
            const auto kTwice = [](int x) {
              return 2 * x;
            };
            const std::vector<Def> kDefs = {
                {"a", [](int x) { return x; }},
                {"b", {}},
            };
            """)
        self.assertEqual(found, {"kTwice (lambda)": 3, "lambda": 1})

    def test_test_macros_keep_their_arguments(self):
        self.assertEqual(functions("""\
            TEST(Suite, Name) {
              EXPECT_EQ(1, 1);
            }
            """), {"TEST(Suite, Name)": 3})


class CommandLine(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        self.addCleanup(self.dir.cleanup)
        body = "".join("  x += %d;\n" % i for i in range(8))
        with open(os.path.join(self.dir.name, "long.cc"), "w") as f:
            f.write("int Long(int x) {\n" + body + "  return x;\n}\n\nint Short() { return 1; }\n")
        with open(os.path.join(self.dir.name, "notes.txt"), "w") as f:
            f.write("int Ignored() {\n}\n")

    def run_main(self, *args):
        out = io.StringIO()
        with redirect_stdout(out):
            rc = cfl.main([self.dir.name, *args])
        return rc, out.getvalue().splitlines()

    def test_over_the_limit(self):
        rc, lines = self.run_main("--max-lines", "10")
        path = os.path.join(self.dir.name, "long.cc")
        self.assertEqual(rc, 1)
        self.assertEqual(lines, ["%s:1: Long is 11 lines (limit 10)" % path])

    def test_within_the_limit(self):
        self.assertEqual(self.run_main("--max-lines", "11"), (0, []))

    def test_top(self):
        rc, lines = self.run_main("--max-lines", "11", "--top", "5")
        self.assertEqual(rc, 0)
        self.assertEqual([l.split(": ", 1)[1] for l in lines],
                         ["Long is 11 lines (limit 11)", "Short is 1 lines (limit 11)"])

    def test_runs_as_a_program(self):
        r = subprocess.run([sys.executable, SCRIPT, self.dir.name, "--max-lines", "5"], capture_output=True,
                           text=True)
        self.assertEqual(r.returncode, 1)
        self.assertIn("Long is 11 lines (limit 5)", r.stdout)


if __name__ == "__main__":
    unittest.main()
