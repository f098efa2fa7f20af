"""Check a real ADE20K model with nrw-etl's segmentation, on a machine that has one.

No ADE20K weights are available offline where nrw-etl is developed, so its accuracy with a
real model is measured by the user, with this script:

  # 1. a released SegFormer, fetched on a machine with network (nrw-etl never downloads):
  huggingface-cli download nvidia/segformer-b0-finetuned-ade-512-512 --local-dir segformer-b0
  # 2. ADE20K SceneParsing validation (ADEChallengeData2016: images/ and annotations/):
  nrw-etl segment --images ADEChallengeData2016/images/validation --weights segformer-b0 --out /tmp/ade-b0
  python3 tests/oracles/segment_check.py --labels /tmp/ade-b0 \\
      --annotations ADEChallengeData2016/annotations/validation \\
      [--model segformer-b0 --images ADEChallengeData2016/images/validation --transformers 50]

It prints the mean IoU over the 150 classes (annotation 0, "other", is ignored; IoU summed
over the whole set, as the ADE20K benchmark does) and pixel accuracy; with --transformers N,
also how often nrw-etl's labels equal Hugging Face transformers' (PIL processor, the model,
post_process_semantic_segmentation) on the first N photos. Needs numpy and Pillow; torch and
transformers only for --transformers.
"""
import argparse
import os
import sys

import numpy as np
from PIL import Image

CLASSES = 150


def pairs(labels_dir, ann_dir):
    for root, _, files in os.walk(ann_dir):
        for f in sorted(files):
            if f.lower().endswith(".png"):
                rel = os.path.relpath(os.path.join(root, f), ann_dir)
                yield rel, os.path.join(labels_dir, rel)


def miou(labels_dir, ann_dir):
    inter = np.zeros(CLASSES + 1, np.int64)
    union = np.zeros(CLASSES + 1, np.int64)
    correct = total = n = 0
    for rel, ours_path in pairs(labels_dir, ann_dir):
        if not os.path.exists(ours_path):
            sys.exit(f"{ours_path}: no label map for annotation {rel} (run nrw-etl segment on the same photos)")
        gt = np.asarray(Image.open(os.path.join(ann_dir, rel)))
        ours = np.asarray(Image.open(ours_path))
        if gt.shape != ours.shape:
            sys.exit(f"{ours_path}: {ours.shape} but the annotation is {gt.shape}")
        valid = gt > 0
        g, o = gt[valid].astype(np.int64), ours[valid].astype(np.int64)
        correct += int((g == o).sum())
        total += int(valid.sum())
        i = np.bincount(g[g == o], minlength=CLASSES + 1)
        a = np.bincount(g, minlength=CLASSES + 1)
        b = np.bincount(o, minlength=CLASSES + 1)
        inter += i
        union += a + b - i
        n += 1
    present = union[1:] > 0
    iou = inter[1:][present] / union[1:][present]
    return n, float(iou.mean()) * 100, correct / max(total, 1) * 100


def agreement(labels_dir, model_dir, images_dir, count):
    import torch
    from transformers import SegformerForSemanticSegmentation
    from transformers.models.segformer.image_processing_pil_segformer import SegformerImageProcessorPil

    torch.set_grad_enabled(False)
    model = SegformerForSemanticSegmentation.from_pretrained(model_dir).eval()
    proc = SegformerImageProcessorPil()
    same = total = 0
    names = sorted(f for f in os.listdir(images_dir) if f.lower().endswith((".jpg", ".jpeg", ".png")))
    for name in names[:count]:
        img = Image.open(os.path.join(images_dir, name)).convert("RGB")
        logits = model(**proc(images=img, return_tensors="pt")).logits
        theirs = proc.post_process_semantic_segmentation(
            type("O", (), {"logits": logits})(), target_sizes=[(img.height, img.width)]
        )[0].numpy() + 1
        ours = np.asarray(Image.open(os.path.join(labels_dir, os.path.splitext(name)[0] + ".png")))
        same += int((ours == theirs).sum())
        total += ours.size
    return same / max(total, 1) * 100


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--labels", required=True, help="label folder written by nrw-etl segment")
    ap.add_argument("--annotations", required=True, help="ADE20K annotations (8-bit PNG ids, 0 = other)")
    ap.add_argument("--model", help="the SegFormer folder, for --transformers")
    ap.add_argument("--images", help="the photos, for --transformers")
    ap.add_argument("--transformers", type=int, default=0, help="compare with transformers on N photos")
    a = ap.parse_args()
    n, m, acc = miou(a.labels, a.annotations)
    print(f"{n} photos: mIoU {m:.2f}%, pixel accuracy {acc:.2f}% (annotation 0 ignored)")
    if a.transformers:
        if not (a.model and a.images):
            sys.exit("--transformers needs --model and --images")
        print(f"labels equal to transformers' on {agreement(a.labels, a.model, a.images, a.transformers):.3f}% of pixels")


if __name__ == "__main__":
    main()
