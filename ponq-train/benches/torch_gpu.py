#!/usr/bin/env python3
"""PyTorch reference timing of the PoNQ network on a GPU (CUDA), the counterpart of
`train_bench --backend wgpu|cuda` and of ../shared/tools/torch_ponqnet.py (which times the CPU).

The network is SPEC section 3's: a 2^3 convolution from 1 to W channels, E 3^3 convolutions,
five decoders of B residual blocks of two 1^3 convolutions, heads of 3P, 3P, 6P, 3P and 1
channels, LeakyReLU(0.01); random weights, f32 (TF32 off, as Burn computes in f32).

  torch_gpu.py [--width W] [--points P] [--enc E] [--blocks B] [--grid N] [--batch K] [--reps R]
               [--device cuda|cpu]

prints one line: the median seconds of a forward (no gradient) and of a training step (forward,
a plain squared loss, backward, AdamW), each timed up to the device's synchronisation.
"""
import argparse
import statistics
import time

import torch
from torch import nn

ap = argparse.ArgumentParser()
ap.add_argument("--width", type=int, default=128)
ap.add_argument("--points", type=int, default=4)
ap.add_argument("--enc", type=int, default=5)
ap.add_argument("--blocks", type=int, default=3)
ap.add_argument("--grid", type=int, default=32, help="cells per side (input: N+1 nodes)")
ap.add_argument("--batch", type=int, default=1)
ap.add_argument("--reps", type=int, default=5)
ap.add_argument("--device", default="cuda", help="cuda (default) or cpu (to try the script)")
a = ap.parse_args()
torch.backends.cudnn.allow_tf32 = False
torch.backends.cuda.matmul.allow_tf32 = False
dev = torch.device(a.device)
sync = torch.cuda.synchronize if dev.type == "cuda" else (lambda: None)
name = torch.cuda.get_device_name() if dev.type == "cuda" else "CPU"
act = nn.LeakyReLU(0.01)


class Decoder(nn.Module):
    def __init__(self, w, out, blocks):
        super().__init__()
        self.blocks = nn.ModuleList(
            [nn.ModuleList([nn.Conv3d(w, w, 1), nn.Conv3d(w, w, 1)]) for _ in range(blocks)]
        )
        self.head = nn.Conv3d(w, out, 1)

    def forward(self, x):
        for c1, c2 in self.blocks:
            x = act(c2(act(c1(x))) + x)
        return self.head(x)


class Net(nn.Module):
    def __init__(self, w, p, enc, blocks):
        super().__init__()
        self.enc = nn.ModuleList(
            [nn.Conv3d(1, w, 2)] + [nn.Conv3d(w, w, 3, padding=1) for _ in range(enc)]
        )
        self.dec = nn.ModuleList(
            [Decoder(w, k * p, blocks) for k in (3, 3, 6, 3)] + [Decoder(w, 1, blocks)]
        )

    def forward(self, x):
        for c in self.enc:
            x = act(c(x))
        return [d(x) for d in self.dec]


net = Net(a.width, a.points, a.enc, a.blocks).to(dev)
params = sum(p.numel() for p in net.parameters())
x = torch.randn(a.batch, 1, a.grid + 1, a.grid + 1, a.grid + 1, device=dev)
opt = torch.optim.AdamW(net.parameters(), 1e-4, amsgrad=True)


def timed(f):
    sync()
    t = time.perf_counter()
    f()
    sync()
    return time.perf_counter() - t


def forward():
    with torch.no_grad():
        net(x)


def step():
    out = net(x)
    loss = sum(o.square().mean() for o in out)
    opt.zero_grad()
    loss.backward()
    opt.step()


for f in (forward, step):
    timed(f)  # warm-up (cuDNN algorithm choice)
fw = statistics.median(timed(forward) for _ in range(a.reps))
st = statistics.median(timed(step) for _ in range(a.reps))
print(
    f"torch {torch.__version__} {name} width={a.width} P={a.points} "
    f"params={params} input={a.grid + 1}^3 batch={a.batch} forward={fw:.4f} step={st:.4f}"
)
