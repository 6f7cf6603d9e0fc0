"""Stage dispatch for ``run.py``: the composed config picks what runs."""

from pathlib import Path

from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig


def run(cfg: DictConfig) -> None:
    """Run the main job in the Hydra run's output folder."""
    from legoh import stand
    from legoh.config import validate

    validate(cfg)
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    stand.main(cfg, out_dir)
