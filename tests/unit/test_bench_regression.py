"""bench/regression.py without builds: its arguments, its table (the builds and runs are
exercised by running it; see bench/README.md)."""
import os
import subprocess
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, REPO)

from bench import regression  # noqa: E402


def test_revs_are_commits_folders_or_named(tmp_path):
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True)
    if head.returncode != 0:
        pytest.skip("not a git checkout")
    r = regression.Rev("HEAD", str(tmp_path))
    assert r.commit == head.stdout.strip() and r.label == r.commit[:7]
    assert r.src == os.path.join(str(tmp_path), "pxsrc-" + r.label)
    assert regression.Rev(REPO, str(tmp_path)).label == "worktree"
    named = regression.Rev(f"new={tmp_path}", "/unused")
    assert (named.label, named.src, named.commit) == ("new", str(tmp_path), None)
    with pytest.raises(SystemExit, match="neither a folder nor a commit"):
        regression.Rev("no-such-commit-or-folder", str(tmp_path))
    with pytest.raises(SystemExit, match="name"):
        regression.Rev(f"bad name={tmp_path}", str(tmp_path))


def test_revs_carry_an_environment_for_their_benches(tmp_path):
    """NAME=REV@VAR=VALUE: the same tree with another environment (one build for both)."""
    wide = regression.Rev(f"w256={tmp_path}@LP_NATIVE_VECTOR_WIDTH=256@X=a=b", "/unused")
    assert (wide.label, wide.src, wide.env) == ("w256", str(tmp_path), {"LP_NATIVE_VECTOR_WIDTH": "256", "X": "a=b"})
    env = regression.bench_env("/site", wide.env)
    assert env["LP_NATIVE_VECTOR_WIDTH"] == "256" and env["PYTHONPATH"].split(os.pathsep)[0] == "/site"
    assert regression.Rev(str(tmp_path), "/unused").env == {}
    with pytest.raises(SystemExit, match="@VAR=VALUE"):
        regression.Rev(f"w={tmp_path}@NOVALUE", "/unused")


def test_table_gives_medians_and_ratios_to_the_first():
    class R:
        def __init__(self, label):
            self.label = label

    revs = [R("old"), R("new")]
    key = ("throughput", "soup 1k", "nee", "G rays/s")
    samples = {key: {"old": [1.0, 3.0, 2.0], "new": [3.0, 2.5, 10.0]},
               ("throughput", "soup 1M", "nee", "G rays/s"): {"new": [1.0]}}
    md = regression.table(revs, samples).splitlines()
    assert md[0] == "| bench | scene | method | figure | old | new | ×old |"
    assert md[2] == "| throughput | soup 1k | nee | G rays/s | 2 | 3 | 1.500 |"
    assert md[3] == "| throughput | soup 1M | nee | G rays/s | — | 1 | — |"  # sizes in numeric order


def test_throughput_figures_by_device_type():
    row = dict(size="100k", order="coherent+sort", rays_per_s=2e9, rays_per_cpu_s=1e6, upload_s=0.1, flatten_s=0.02)
    gpu = regression.throughput_figures({"info": {"device_type": "discrete", "method": "nee"}, "rows": [row]})
    assert gpu == {("throughput", "soup 100k", "nee", "G rays/s"): 2.0,
                   ("throughput", "soup 100k", "nee", "upload s"): 0.1,
                   ("throughput", "soup 100k", "nee", "flatten s"): 0.02}
    cpu = regression.throughput_figures({"info": {"device_type": "cpu", "method": "nee"},
                                         "rows": [dict(row, order="shuffled+sort")]})
    assert cpu[("throughput", "soup 100k shuffled+sort", "nee", "M rays/CPU-s")] == 1.0


def test_frame_cost_needs_npz():
    with pytest.raises(SystemExit, match="--npz"):
        regression.main(["HEAD", "--benches", "frame_cost"])


def test_frame_cost_leaves_out_settings_an_old_build_lacks():
    from bench import frame_cost

    off = dict(method="nee", ic=False, rrs="off", guiding=False, guiding_parallax=True)
    assert frame_cost.supported(off, {"method", "ic"}) == {"method": "nee", "ic": False}
    with pytest.raises(ValueError, match="lacks the settings"):
        frame_cost.supported(dict(off, guiding=True), {"method", "ic"})
    with pytest.raises(ValueError, match="lacks the settings"):
        frame_cost.supported(dict(off, rrs="ears"), {"method", "ic"})
    assert frame_cost.supported(dict(off, guiding=True), set(off)) == dict(off, guiding=True)
    assert frame_cost.supported(dict(off, rrs="ears"), set(off)) == dict(off, rrs="ears")


def test_frame_cost_gives_a_build_before_rrs_its_adrrs():
    """Builds before issue 34 switch ADRRS with the bool adrrs (bench/regression.py runs this
    tree's frame_cost against them): rrs off / adrrs becomes adrrs False / True; EARS they lack."""
    from bench import frame_cost

    old = {"method", "ic", "adrrs", "guiding", "guiding_parallax"}
    off = dict(method="mis", ic=False, rrs="off", guiding=False, guiding_parallax=True)
    assert frame_cost.supported(off, old) == dict(method="mis", ic=False, adrrs=False, guiding=False,
                                                  guiding_parallax=True)
    assert frame_cost.supported(dict(off, rrs="adrrs"), old)["adrrs"] is True
    with pytest.raises(ValueError, match="this build has no rrs=ears"):
        frame_cost.supported(dict(off, rrs="ears"), old)
    # Where the build has rrs, or neither name, nothing is renamed.
    assert frame_cost.for_build(dict(off, rrs="adrrs"), old | {"rrs"}) == dict(off, rrs="adrrs")
    assert frame_cost.for_build(dict(off, rrs="adrrs"), {"method"}) == dict(off, rrs="adrrs")
