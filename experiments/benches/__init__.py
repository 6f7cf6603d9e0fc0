"""The project's benchmarks, one module each, run by ``python experiments/bench.py NAME``.

Each module gives ``RESULTS`` (its results file's stem), ``TITLE``, ``TORCH_THREADS`` (None:
torch's default), ``add_arguments(parser)``, ``measure(args) -> dict`` and
``markdown(run) -> str``; optionally ``kind(args) -> str`` (runs of another kind, e.g.
``--quick`` or another device, keep their own newest table) and ``summary(run) -> str``
(its line in the history). ``common`` keeps the history.
"""

# CLI name -> (module, what it measures); listed without importing the benchmarks
BENCHMARKS = {
    "env": ("env", "HikingEnv speed against the raw physics ceiling and two peers"),
    "train": ("train", "the oracle loop: bare env, collection, update and loop frames/s"),
    "student": ("student", "the student loop beside the oracle loop, and where its time goes"),
    "depth": ("depth", "depth on the CPU: the ray-march against mj_multiRay and the physics"),
    "contacts": ("contacts", "what the feet's colliders cost: contacts, env and loop speed"),
    "collect": ("collect", "oracle training frames/s with 1 and 2 collector processes"),
    "export": ("export", "deployment latency of the exported students, one robot, one core"),
    "terrain": ("terrain", "build time and peak memory of the terrain map"),
    "warp-chunks": ("warp_chunks", "height-field chunk size per physics backend"),
    "model-size": ("model_size", "TC-ViTs parameters, FLOPs and CPU latency beside the paper"),
}
