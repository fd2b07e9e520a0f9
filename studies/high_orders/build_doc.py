"""Fill doc_template.md with the generated tables -> docs/validation-high-orders.md.

usage: python3 build_doc.py [OUT.md]   (in the folder of the runs' npz files)"""
import os
import re
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent

def run(*args):
    script, *rest = args
    return subprocess.run([sys.executable, str(HERE / script), *rest], capture_output=True, text=True, check=True,
                          cwd=os.getcwd()).stdout

def clean(t):
    return "\n".join(l for l in t.strip("\n").splitlines() if not l.startswith("<!-- section")).strip("\n")

t = open(HERE / "doc_template.md").read()
for sec in ("base", "decomp", "boot", "fix", "xi", "flag", "hcov"):
    t = t.replace("{{%s}}" % sec, clean(run("tables.py", sec)))
fc = run("final_checks.py")
rows = []
for line in fc.split("\n2b.")[0].split("\n2.")[1].splitlines()[1:]:
    m = re.match(r"\s+(\S+)\s+n=(\d+): base ([\d. ]+) \| w1.5 ([\d. ]+) ; bad (\S+)", line)
    if m:
        cfg = {"OO": "OO", "IO": "IO", "IO0": "IO, unknown_input_std=0"}[m.group(1)]
        rows.append(f"| {cfg} | {m.group(2)} | {m.group(3).strip()} | {m.group(4).strip()} (bad poles excluded: {m.group(5)}) |")
t = t.replace("{{xiclean}}", "\n".join(rows))
t = t.replace("{{flagcheck}}", "```text\n" + run("flagcheck.py", "mc5_300.npz", "w1.5").strip() + "\n```")
assert "{{" not in t
out = Path(sys.argv[1]) if len(sys.argv) > 1 else HERE.parents[1] / "docs" / "validation-high-orders.md"
out.write_text(t)
print("written", len(t))
