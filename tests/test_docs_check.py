"""validation/docs_check.py (issue 31.3): how it reads a doc and compares what a command
printed with what the doc says, at the precision the doc shows."""
import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("docs_check", ROOT / "validation" / "docs_check.py")
dc = importlib.util.module_from_spec(spec)
sys.modules["docs_check"] = dc            # dataclasses look their module up there
spec.loader.exec_module(dc)

DOC = '''# doc
```bash
# (not run by the docs check: needs the gyro)
fogmon monitor --serial /dev/ttyUSB0
fogmon sim --model m.toml \\
    --out sim.csv  # a comment
python3 -m venv .venv && . .venv/bin/activate && pip install -e . && fogmon replay sim.csv
```
```text
  k1_pos    +30.3729 +/- 0.92  deg/h per degC/s
peak-to-peak drift: 1.593 deg/h -> ... (4.8x smaller)
```
The drift falls to 0.33 deg/h. <!-- docs-check: 0.33 deg/h -->
'''


def test_commands_skips_outputs_and_quotes(tmp_path):
    (tmp_path / "doc.md").write_text(DOC)
    cmds = dc.parse_doc(tmp_path / "doc.md", "doc.md")
    assert [c.text for c in cmds] == ["fogmon monitor --serial /dev/ttyUSB0",
                                      "fogmon sim --model m.toml  --out sim.csv  # a comment",
                                      "fogmon replay sim.csv"]
    assert [c.skip for c in cmds] == ["needs the gyro", "", ""]
    assert [n for n, _ in cmds[2].expected] == [10, 11] and cmds[2].quotes == [(13, "0.33 deg/h")]


def test_numbers_compare_at_the_precision_the_doc_shows():
    assert dc.same_token("30.4", "30.37") and not dc.same_token("30.4", "30.46")
    assert dc.same_token("6.3e+02", "630.2") and dc.same_token("0.33", "0.3309") and not dc.same_token("0.33", "0.3359")
    assert dc.tokens("k1_pos +30.37 (4.8x smaller)") == ["k1_pos", "+30.37", "(", "4.8", "x", "smaller)"]


def test_a_changed_number_is_a_mismatch_naming_both_lines():
    cmd = dc.Command("doc.md", 2, "bash", "x", expected=[(10, "k1_pos +30.04 +/- 0.37  deg/h per degC/s"),
                                                         (11, "drift 1.79 -> ... (4.8x smaller)")],
                     quotes=[(13, "0.33")])
    printed = "thermal\n  k1_pos    +30.3729 +/- 0.92  deg/h per degC/s\ndrift 1.593 -> 0.3309 (4.8x smaller)\n"
    bad = dc.compare(cmd, printed)
    assert len(bad) == 2 and "+30.04" in bad[0] and "+30.3729" in bad[0] and "1.79" in bad[1]
    assert dc.compare(cmd, printed.replace("30.3729 +/- 0.92", "30.04 +/- 0.37").replace("1.593", "1.79")) == []


def test_a_python_block_keeps_its_indentation(tmp_path):
    (tmp_path / "doc.md").write_text("```python\nclass A:\n    x = 1\n```\n"
                                     "- item:\n  ```python\n  if True:\n      y = 2\n  ```\n")
    cmds = dc.parse_doc(tmp_path / "doc.md", "doc.md")
    assert [c.text for c in cmds] == ["class A:\n    x = 1", "if True:\n    y = 2"]
