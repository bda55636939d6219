"""A toy object-centric training loop on a clevrtex dataset, end to end (run in CI by
`tests/python_package.rs` where torch is installed: `./scripts/setup.sh --torch`).

    python examples/train_toy.py                  # generates a tiny dataset with `clevrtex`
    python examples/train_toy.py --data DIR       # or trains on a dataset you have

It loads the dataset through `torch.utils.data.DataLoader` (batch 8, 2 workers,
`clevrtex.collate`) with per-object masks and depth, trains a few steps of a small model that
splits each image into K soft masks and paints each with one colour (about 3,000 parameters),
and scores the predicted masks with `clevrtex.Evaluator`. The last line printed is a JSON
summary.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile

import torch
from torch import nn
from torch.utils.data import DataLoader

import clevrtex

K = 6  # slots of the model
MAX_OBJECTS = 10  # ClevrTex's most objects per image: the per-object arrays' K


class ToySlots(nn.Module):
    """RGB + depth in, K soft masks out; each slot's colour is the mask-weighted mean of the
    image, and the reconstruction paints every mask with its slot's colour."""

    def __init__(self, k: int = K) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Conv2d(4, 16, 3, padding=1),
            nn.ReLU(),
            nn.Conv2d(16, 16, 3, padding=1),
            nn.ReLU(),
            nn.Conv2d(16, k, 1),
        )

    def forward(self, image: torch.Tensor, depth: torch.Tensor):
        # Depth in metres, +inf where the camera sees nothing: bounded for the network.
        d = torch.where(torch.isfinite(depth), depth, torch.zeros_like(depth))
        d = d / d.amax(dim=(1, 2, 3), keepdim=True).clamp(min=1e-6)
        masks = self.net(torch.cat([image, d], dim=1)).softmax(dim=1)  # (B, K, H, W)
        w = masks.unsqueeze(2)  # (B, K, 1, H, W)
        colour = (w * image.unsqueeze(1)).sum(dim=(3, 4)) / w.sum(dim=(3, 4)).clamp(min=1e-6)
        recon = (w * colour[..., None, None]).sum(dim=1)  # (B, 3, H, W)
        return recon, masks


def make_dataset(clevrtex_bin: str, out: str, n: int) -> None:
    cmd = [clevrtex_bin, "generate", "--variant", "clevr", "-n", str(n), "--width", "64", "--height", "48",
           "--samples", "4", "--passes", "rgb,mask,depth", "--out", out]
    print("+", " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", help="a dataset folder (default: generate 16 tiny images)")
    ap.add_argument("--variant", default="clevr")
    ap.add_argument("--clevrtex", default=os.environ.get("CLEVRTEX_BIN", "clevrtex"), help="the clevrtex binary")
    ap.add_argument("--steps", type=int, default=12)
    ap.add_argument("--side", type=int, default=32)
    args = ap.parse_args()
    torch.manual_seed(0)
    tmp = None
    data = args.data
    if data is None:
        tmp = tempfile.TemporaryDirectory(prefix="clevrtex-toy-")
        data = os.path.join(tmp.name, "data")
        make_dataset(args.clevrtex, data, 16)

    ds = clevrtex.Dataset(data, args.variant, split="all", resize=(args.side, args.side), as_dict=True,
                          passes=("depth",), max_objects=MAX_OBJECTS)
    loader = DataLoader(ds, batch_size=8, shuffle=True, num_workers=2, collate_fn=clevrtex.collate,
                        generator=torch.Generator().manual_seed(0), persistent_workers=True)
    model = ToySlots()
    params = sum(p.numel() for p in model.parameters())
    opt = torch.optim.Adam(model.parameters(), lr=3e-3)
    losses = []
    step = 0
    while step < args.steps:
        for batch in loader:
            b = batch["image"].shape[0]
            assert batch["object_masks"].shape == (b, MAX_OBJECTS, args.side, args.side), batch["object_masks"].shape
            assert batch["depth"].dtype == torch.float32 and batch["visibility"].dtype == torch.bool
            # Every visible object has pixels in its mask; padded slots have none.
            assert torch.equal(batch["object_masks"].flatten(2).any(-1), batch["visibility"])
            recon, masks = model(batch["image"], batch["depth"])
            loss = ((recon - batch["image"]) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
            losses.append(loss.item())
            print(f"step {step}: loss {loss.item():.5f}", flush=True)
            step += 1
            if step == args.steps:
                break

    ev = clevrtex.Evaluator()
    model.eval()
    eval_loader = DataLoader(ds, batch_size=8, num_workers=2, collate_fn=clevrtex.collate)
    with torch.no_grad():
        for batch in eval_loader:
            recon, masks = model(batch["image"], batch["depth"])
            ev.update(recon, masks.unsqueeze(2), batch["image"], batch["mask"], batch["metadata"])
    summary = {
        "parameters": params,
        "images": len(ds),
        "steps": len(losses),
        "first_loss": losses[0],
        "last_loss": losses[-1],
        "mIoU": ev.statistic("mIoU"),
        "ARI_FG": ev.statistic("ARI_FG"),
    }
    print(json.dumps(summary), flush=True)
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
