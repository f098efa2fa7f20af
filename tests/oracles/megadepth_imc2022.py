"""IMC 2022's training files of a `--layout megadepth` export, read as the organisers' evaluation
code reads them, checked against what D2-Net's own preprocess_scene.py wrote for the same
export. Prints one JSON object.

Transcribed from the organisers' evaluation code (Kaggle "IMC 2022", the helper file shared by
its tutorial and validation notebooks): `ReadCovisibilityData` (csv.reader, header skipped,
`covisibility_dict[row[0]] = float(row[1])`, `F_dict[row[0]]` from `row[2].split(' ')`),
`LoadCalibration` (K and R reshaped to 3 × 3 from `split(' ')`, T a vector),
`ComputeFundamentalMatrix`, `DecomposeFundamentalMatrixWithIntrinsics`,
`QuaternionFromMatrix`, `ComputeErrorForOneExample`, `EvaluateSubmission`'s
`image_id_1, image_id_2 = pair.split('-')` and relative ground truth
(`dR_gt = R2 R1ᵀ`, `dT_gt = T2 − dR_gt T1`), and the scaling dictionary read from
`scaling_factors.csv` (header skipped, `scaling_dict[row[0]] = float(row[1])`). Images are
read with `cv2.imread(f'{src}/{scene}/images/{image_id}.jpg')` as the tutorial does.

The covisibility is recomputed here from D2-Net's `points3D_id_to_2D` dicts: the shared
points' bounding box in each image over its area, the smaller of the two.

usage: megadepth_imc2022.py EXPORT D2NET_SCENE_INFO.npz SCENE
"""

import csv
import json
import os.path as osp
import sys
from collections import namedtuple

import cv2
import numpy as np

root, theirs_path, scene = sys.argv[1], sys.argv[2], sys.argv[3]
theirs = np.load(theirs_path, allow_pickle=True)
src = osp.join(root, "imc2022", "train")

Gt = namedtuple("Gt", ["K", "R", "T"])
eps = 1e-15


def ReadCovisibilityData(filename):
    covisibility_dict = {}
    F_dict = {}
    with open(filename) as f:
        reader = csv.reader(f, delimiter=",")
        for i, row in enumerate(reader):
            if i == 0:
                continue
            covisibility_dict[row[0]] = float(row[1])
            F_dict[row[0]] = np.array([float(v) for v in row[2].split(" ")])
    return covisibility_dict, F_dict


def LoadCalibration(filename):
    calib_dict = {}
    with open(filename, "r") as f:
        reader = csv.reader(f, delimiter=",")
        for i, row in enumerate(reader):
            if i == 0:
                continue
            camera_id = row[0]
            K = np.array([float(v) for v in row[1].split(" ")]).reshape([3, 3])
            R = np.array([float(v) for v in row[2].split(" ")]).reshape([3, 3])
            T = np.array([float(v) for v in row[3].split(" ")])
            calib_dict[camera_id] = Gt(K=K, R=R, T=T)
    return calib_dict


def QuaternionFromMatrix(matrix):
    M = np.array(matrix, dtype=np.float64)[:4, :4]
    m00, m01, m02 = M[0, 0], M[0, 1], M[0, 2]
    m10, m11, m12 = M[1, 0], M[1, 1], M[1, 2]
    m20, m21, m22 = M[2, 0], M[2, 1], M[2, 2]
    K = np.array([[m00 - m11 - m22, 0.0, 0.0, 0.0],
                  [m01 + m10, m11 - m00 - m22, 0.0, 0.0],
                  [m02 + m20, m12 + m21, m22 - m00 - m11, 0.0],
                  [m21 - m12, m02 - m20, m10 - m01, m00 + m11 + m22]])
    K /= 3.0
    w, V = np.linalg.eigh(K)
    q = V[[3, 0, 1, 2], np.argmax(w)]
    if q[0] < 0:
        np.negative(q, q)
    return q


def ComputeFundamentalMatrix(K1, K2, R1, R2, T1, T2):
    dR = np.dot(R2, R1.T)
    dT = (T2 - np.dot(dR, T1)).flatten()
    A = np.dot(K1, np.dot(dR.T, dT))
    C = np.array([[0, -A[2], A[1]], [A[2], 0, -A[0]], [-A[1], A[0], 0]])
    return np.matmul(np.linalg.inv(K2).T, np.matmul(dR, np.matmul(K1.T, C)))


def DecomposeFundamentalMatrixWithIntrinsics(F, K1, K2):
    E = np.matmul(K2.T, np.matmul(F, K1))
    U, S, Vh = np.linalg.svd(E)
    if np.linalg.det(U) < 0:
        U *= -1
    if np.linalg.det(Vh) < 0:
        Vh *= -1
    W = np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 1]])
    R_a = np.matmul(U, np.matmul(W, Vh))
    R_b = np.matmul(U, np.matmul(W.T, Vh))
    T = U[:, -1]
    return R_a, R_b, T


def ComputeErrorForOneExample(q_gt, T_gt, q, T, scale):
    q_gt_norm = q_gt / (np.linalg.norm(q_gt) + eps)
    q_norm = q / (np.linalg.norm(q) + eps)
    loss_q = np.maximum(eps, (1.0 - np.sum(q_norm * q_gt_norm) ** 2))
    err_q = np.arccos(1 - 2 * loss_q)
    T_gt_scaled = T_gt * scale
    T_scaled = T * np.linalg.norm(T_gt) * scale / (np.linalg.norm(T) + eps)
    err_t = min(np.linalg.norm(T_gt_scaled - T_scaled), np.linalg.norm(T_gt_scaled + T_scaled))
    return err_q * 180 / np.pi, err_t


out = {"problems": []}
problems = out["problems"]

scaling_dict = {}
with open(f"{src}/scaling_factors.csv") as f:
    reader = csv.reader(f, delimiter=",")
    for i, row in enumerate(reader):
        if i == 0:
            continue
        scaling_dict[row[0]] = float(row[1])
out["scaling_dict"] = scaling_dict
scale = scaling_dict[scene]

calib_dict = LoadCalibration(f"{src}/{scene}/calibration.csv")
covisibility_dict, F_dict = ReadCovisibilityData(f"{src}/{scene}/pair_covisibility.csv")

# D2-Net's views by image id (the file stem of its image path).
ids = [osp.splitext(osp.basename(p))[0] for p in theirs["image_paths"]]
out["views"] = len(ids)
if sorted(calib_dict) != sorted(ids):
    problems.append(f"calibration ids {sorted(calib_dict)} != {sorted(ids)}")
sizes = {}
for k, image_id in enumerate(ids):
    gt = calib_dict.get(image_id)
    if gt is None:
        continue
    if not np.array_equal(gt.K, theirs["intrinsics"][k]):
        problems.append(f"{image_id}: K {gt.K.tolist()} != D2-Net's")
    pose = theirs["poses"][k]
    if np.max(np.abs(gt.R - pose[:3, :3])) > 1e-15 or np.max(np.abs(gt.T - pose[:3, 3])) > 1e-12:
        problems.append(f"{image_id}: R, T differ from D2-Net's pose")
    image = cv2.imread(f"{src}/{scene}/images/{image_id}.jpg")
    if image is None:
        problems.append(f"{image_id}: cv2.imread read nothing")
        continue
    sizes[image_id] = image.shape[:2]


def covisibility(i, j):
    """From D2-Net's dicts: the shared points' box in each image over its area, the smaller."""
    a, b = theirs["points3D_id_to_2D"][i], theirs["points3D_id_to_2D"][j]
    shared = [p for p in a if p in b]
    shares = []
    for d, image_id in ((a, ids[i]), (b, ids[j])):
        xy = np.array([d[p] for p in shared])
        h, w = sizes[image_id]
        extent = xy.max(axis=0) - xy.min(axis=0)
        shares.append(extent[0] * extent[1] / (w * h))
    return min(shares)


overlap = theirs["overlap_matrix"]
n = len(ids)
want = {}
for i in range(n):
    for j in range(i + 1, n):
        if overlap[i, j] > 0:
            key1, key2 = max(ids[i], ids[j]), min(ids[i], ids[j])
            want[f"{key1}-{key2}"] = (i, j)
if sorted(covisibility_dict) != sorted(want):
    problems.append(f"pairs {sorted(covisibility_dict)} != {sorted(want)}")

worst = {"covisibility": 0.0, "F_relative": 0.0, "err_q_deg": 0.0, "err_t": 0.0}
recommended = 0
for pair, (i, j) in want.items():
    if pair not in covisibility_dict:
        continue
    image_id_1, image_id_2 = pair.split("-")
    if image_id_1 <= image_id_2:
        problems.append(f"{pair}: key1 is not the larger id")
    c = covisibility(i, j)
    worst["covisibility"] = max(worst["covisibility"], abs(covisibility_dict[pair] - c))
    recommended += covisibility_dict[pair] >= 0.1
    K1, R1_gt, T1_gt = calib_dict[image_id_1].K, calib_dict[image_id_1].R, calib_dict[image_id_1].T.reshape((3, 1))
    K2, R2_gt, T2_gt = calib_dict[image_id_2].K, calib_dict[image_id_2].R, calib_dict[image_id_2].T.reshape((3, 1))
    F_theirs = ComputeFundamentalMatrix(K1, K2, R1_gt, R2_gt, T1_gt, T2_gt)
    F = F_dict[pair].reshape([3, 3])
    rel = np.max(np.abs(F - F_theirs)) / np.max(np.abs(F_theirs))
    worst["F_relative"] = max(worst["F_relative"], rel)
    # The export's F, submitted as a prediction, scores as the ground truth.
    R_pred_a, R_pred_b, T_pred = DecomposeFundamentalMatrixWithIntrinsics(F, K1, K2)
    q_pred_a = QuaternionFromMatrix(R_pred_a)
    q_pred_b = QuaternionFromMatrix(R_pred_b)
    dR_gt = np.dot(R2_gt, R1_gt.T)
    dT_gt = (T2_gt - np.dot(dR_gt, T1_gt)).flatten()
    q_gt = QuaternionFromMatrix(dR_gt)
    q_gt = q_gt / (np.linalg.norm(q_gt) + eps)
    err_q_a, err_t_a = ComputeErrorForOneExample(q_gt, dT_gt, q_pred_a, T_pred, scale)
    err_q_b, err_t_b = ComputeErrorForOneExample(q_gt, dT_gt, q_pred_b, T_pred, scale)
    worst["err_q_deg"] = max(worst["err_q_deg"], min(err_q_a, err_q_b))
    worst["err_t"] = max(worst["err_t"], err_t_a)
out["pairs"] = len(covisibility_dict)
out["recommended"] = int(recommended)
out["worst"] = worst
json.dump(out, sys.stdout)
