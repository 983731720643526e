"""darkread's lab: what measures the product and does research on it (evaluation, benchmarks,
reading-gaze analysis, the research parts of training and synthesis, the simulator's truth, test
fixtures). Installed as ``darkread.lab``; nothing outside ``lab/`` imports it.
"""

from pathlib import Path

NETWORKS_DIR = Path(__file__).resolve().parent / "networks"
PREVIOUS_NETWORK = NETWORKS_DIR / "binary_unet_previous.onnx"
FULL_NETWORK = NETWORKS_DIR / "binary_unet_full.onnx"
BAND_NETWORK = NETWORKS_DIR / "binary_unet_band.onnx"
