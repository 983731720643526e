"""What makes and ships the reconstruction network: the shipped ONNX files (in this folder),
synthetic data (``synth/``) and training (``train/``)."""

from pathlib import Path

MODELS_DIR = Path(__file__).resolve().parent  # the shipped .onnx files and the model card
FIGURE_PATH = MODELS_DIR.parent / "docs" / "model_samples.png"  # the card's sample figure (a checkout's docs/)
