"""docs/python.md's training loop runs on the demo dataset and its loss is finite."""

import math
import os
import re
import subprocess
import sys

import pytest

pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch)")

DOC = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "python.md")


def test_the_training_loop_in_the_docs_runs(demo, tmp_path):
    blocks = re.findall(r"```python\n(.*?)```", open(DOC).read(), re.S)
    loop = [b for b in blocks if "TripletMarginLoss" in b]
    assert len(loop) == 1
    script = tmp_path / "train.py"
    script.write_text(loop[0])
    out = subprocess.run([sys.executable, str(script), demo], capture_output=True, text=True,
                         cwd=tmp_path, timeout=600)
    assert out.returncode == 0, out.stderr
    losses = [float(m) for m in re.findall(r"loss (\S+)", out.stdout)]
    assert len(losses) == 12, out.stdout  # 2 epochs x 24 triplets / batches of 4
    assert all(math.isfinite(x) for x in losses)
