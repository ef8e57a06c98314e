"""Packs an installed distribution back into its wheel: ``python scripts/wheel_from_installed.py
pyoidn OUT_DIR`` writes OUT_DIR/pyoidn-<version>-<tag>.whl from this Python's site-packages.

`make extension` bundles pyoidn (the OIDN library the denoiser falls back to, for Blenders
without OIDN) this way, from the version scripts/requirements.txt installed, without
downloading; the tests do the same. The wheel holds the files the installed RECORD lists, minus
what the installer added (INSTALLER, REQUESTED, direct_url.json), with a new RECORD (PEP 427).
"""
import base64
import hashlib
import importlib.metadata
import os
import sys
import zipfile

INSTALLER_FILES = {"INSTALLER", "REQUESTED", "direct_url.json", "RECORD"}


def _hash(data):
    return "sha256=" + base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()


def wheel_from_installed(name, out_dir):
    """Path of the wheel written for the installed distribution ``name``."""
    dist = importlib.metadata.distribution(name)
    info = next(f for f in dist.files if f.name == "WHEEL" and f.parent.name.endswith(".dist-info"))
    dist_info = str(info.parent)
    tags = [line.split(":", 1)[1].strip() for line in dist.read_text("WHEEL").splitlines() if line.startswith("Tag:")]
    if len(tags) != 1:
        raise ValueError(f"{name}: expected one wheel tag, found {tags}")
    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, f"{dist.metadata['Name'].replace('-', '_')}-{dist.version}-{tags[0]}.whl")
    record = []
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as wheel:
        for f in dist.files:
            rel = str(f)
            if rel.startswith("..") or "__pycache__" in rel or (
                    str(f.parent) == dist_info and f.name in INSTALLER_FILES):
                continue
            data = f.locate().read_bytes()
            wheel.writestr(rel, data)
            record.append(f"{rel},{_hash(data)},{len(data)}")
        record.append(f"{dist_info}/RECORD,,")
        wheel.writestr(f"{dist_info}/RECORD", "\n".join(record) + "\n")
    return path


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: wheel_from_installed.py DISTRIBUTION OUT_DIR")
    print(wheel_from_installed(sys.argv[1], sys.argv[2]))
