"""Calibration targets (ChArUco or ArUco grid boards) and their detection with OpenCV's aruco module.

OpenCV 5 only has the detector objects (``cv2.aruco.ArucoDetector``, ``cv2.aruco.CharucoDetector``);
the old free functions are gone. A board is described by a small JSON file (``board.json``) so the
capture, the synthetic generator and the calibration commands agree on its geometry.

Board frame: origin at the board's top-left corner, x along the columns (right on the printout),
y along the rows (down on the printout), z into the board; metres.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np

from darkread.core.json_file import read_json_file
from darkread.edge.errors import CalibrationError

BOARD_NAME = "board.json"
KINDS = ("charuco", "grid")


@dataclass(frozen=True)
class BoardSpec:
    """A printed or displayed target.

    ``charuco``: ``squares_x`` x ``squares_y`` chessboard squares of ``square_m`` with markers of
    ``marker_m`` in the white squares; corners are the inner chessboard corners.
    ``grid``: ``squares_x`` x ``squares_y`` ArUco markers of ``marker_m`` spaced ``square_m - marker_m``
    apart; corners are the four corners of every marker.
    """

    kind: str = "charuco"
    squares_x: int = 7
    squares_y: int = 5
    square_m: float = 0.04
    marker_m: float = 0.03
    dictionary: str = "DICT_4X4_50"

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise CalibrationError(f"board kind {self.kind!r} is not one of {KINDS}")
        if self.squares_x < 2 or self.squares_y < 2:
            raise CalibrationError("a board needs at least 2 x 2 squares")
        if not 0 < self.marker_m < self.square_m:
            raise CalibrationError(f"marker_m ({self.marker_m}) must be positive and smaller than square_m ({self.square_m})")
        if not hasattr(cv2.aruco, self.dictionary):
            raise CalibrationError(f"unknown ArUco dictionary {self.dictionary!r} (e.g. DICT_4X4_50)")

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) of the pattern in metres."""
        if self.kind == "charuco":
            return self.squares_x * self.square_m, self.squares_y * self.square_m
        gap = self.square_m - self.marker_m
        return self.squares_x * self.square_m - gap, self.squares_y * self.square_m - gap

    def aruco_dictionary(self) -> cv2.aruco.Dictionary:
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))

    def board(self) -> cv2.aruco.Board:
        if self.kind == "charuco":
            return self.charuco_board()
        return cv2.aruco.GridBoard(
            (self.squares_x, self.squares_y), self.marker_m, self.square_m - self.marker_m, self.aruco_dictionary()
        )

    def charuco_board(self) -> cv2.aruco.CharucoBoard:
        return cv2.aruco.CharucoBoard((self.squares_x, self.squares_y), self.square_m, self.marker_m, self.aruco_dictionary())

    def image(self, px_per_m: float) -> np.ndarray:
        """The pattern as uint8 (0 = black, 255 = white), no margin: pixel (i, j) covers board
        x in [j, j + 1) / px_per_m, y in [i, i + 1) / px_per_m."""
        w_m, h_m = self.size_m
        size = (round(w_m * px_per_m), round(h_m * px_per_m))
        return self.board().generateImage(size, marginSize=0, borderBits=1)

    def to_dict(self) -> dict:
        return asdict(self)

    @staticmethod
    def from_dict(doc: dict) -> BoardSpec:
        try:
            return BoardSpec(
                kind=str(doc.get("kind", "charuco")),
                squares_x=int(doc["squares_x"]),
                squares_y=int(doc["squares_y"]),
                square_m=float(doc["square_m"]),
                marker_m=float(doc["marker_m"]),
                dictionary=str(doc.get("dictionary", "DICT_4X4_50")),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise CalibrationError(f"board description is incomplete or malformed: {exc!r}") from exc


def save_board(path: str | Path, spec: BoardSpec) -> None:
    Path(path).write_text(json.dumps(spec.to_dict(), indent=2) + "\n", encoding="utf-8")


def load_board(path: str | Path) -> BoardSpec:
    path = Path(path)
    doc = read_json_file(path, "board description", error=CalibrationError, missing="pass --board BOARD.json")
    return BoardSpec.from_dict(doc)


@dataclass
class Detection:
    """Board corners found in one image: object points (board frame, m) and image points (px)."""

    object_points: np.ndarray  # (N, 3) float32
    image_points: np.ndarray  # (N, 2) float32
    ids: np.ndarray  # (N,) corner ids (ChArUco) or marker id * 4 + corner (grid)
    n_markers: int

    def __len__(self) -> int:
        return int(self.ids.shape[0])


def detector_parameters() -> cv2.aruco.DetectorParameters:
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    return params


def detect_board(image: np.ndarray, spec: BoardSpec, *, min_corners: int = 6) -> Detection | None:
    """Corners of ``spec`` in a grey image (uint8), or None when too few are found."""
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if spec.kind == "charuco":
        charuco = spec.charuco_board()
        detector = cv2.aruco.CharucoDetector(charuco)
        detector.setDetectorParameters(detector_parameters())
        corners, corner_ids, marker_corners, marker_ids = detector.detectBoard(image)
        n_markers = 0 if marker_ids is None else len(marker_ids)
        if corner_ids is None or len(corner_ids) < min_corners:
            return None
        found = np.asarray(corner_ids).reshape(-1)
        object_points = np.asarray(charuco.getChessboardCorners())[found].astype(np.float32)
        return Detection(object_points, corners.reshape(-1, 2).astype(np.float32), found.astype(np.int64), n_markers)
    board = spec.board()
    aruco = cv2.aruco.ArucoDetector(spec.aruco_dictionary(), detector_parameters())
    marker_corners, marker_ids, _ = aruco.detectMarkers(image)
    if marker_ids is None or 4 * len(marker_ids) < min_corners:
        return None
    known = {int(i): k for k, i in enumerate(np.asarray(board.getIds()).reshape(-1))}
    objects = board.getObjPoints()
    obj: list[np.ndarray] = []
    img: list[np.ndarray] = []
    ids: list[np.ndarray] = []
    for corners, marker_id in zip(marker_corners, marker_ids.reshape(-1)):
        k = known.get(int(marker_id))
        if k is None:
            continue
        obj.append(np.asarray(objects[k], dtype=np.float32).reshape(4, 3))
        img.append(corners.reshape(4, 2))
        ids.append(int(marker_id) * 4 + np.arange(4))
    if len(obj) * 4 < min_corners:
        return None
    return Detection(
        np.concatenate(obj).astype(np.float32), np.concatenate(img).astype(np.float32), np.concatenate(ids), len(obj)
    )


def board_pose(
    detection: Detection, camera_matrix: np.ndarray, dist_coeffs: np.ndarray | None
) -> tuple[np.ndarray, float]:
    """4x4 ``T_camera_board`` by solvePnP (iterative, refined with LM) and its RMS reprojection error (px)."""
    obj = detection.object_points.astype(np.float64)
    img = detection.image_points.astype(np.float64)
    dist = np.zeros(4) if dist_coeffs is None else np.asarray(dist_coeffs, dtype=np.float64)
    ok, rvec, tvec = cv2.solvePnP(obj, img, camera_matrix, dist, flags=cv2.SOLVEPNP_IPPE if len(obj) >= 4 else 0)
    if not ok:
        raise CalibrationError("solvePnP found no board pose (too few or degenerate corners)")
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, camera_matrix, dist, rvec, tvec)
    projected, _ = cv2.projectPoints(obj, rvec, tvec, camera_matrix, dist)
    rms = float(np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - img) ** 2, axis=1))))
    return pose_matrix(rvec, tvec), rms


def pose_matrix(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3))[0]
    T[:3, 3] = np.asarray(tvec, dtype=np.float64).reshape(3)
    return T
