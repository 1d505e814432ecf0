#!/usr/bin/env python3
"""softtouch's default SVAE in PyTorch, to time training side by side with softtouch.

`softtouch bench train --torch PYTHON` runs this once per configuration, interleaved
with its own measurement, and reads the last JSON line it prints. The network, the loss
and the step are the trainer's (trainer/src/model/mod.rs, trainer/src/loss.rs,
trainer/src/train/bench.rs), written again here:

- encoder: a stride-2 3x3 stem to S/2 with `width` channels (no bias, batch norm, ReLU),
  then residual stages that halve the size and double the channels (capped at 8x
  width) until the map is 4x4; each stage is conv3x3(stride 2)-BN-ReLU, conv3x3-BN,
  plus a 1x1 stride-2 skip with bias, then ReLU;
- heads: linear mean and log-variance (clamped to +-30) of `latent` dimensions;
- decoder: linear to the 4x4 top map, ReLU, stride-2 4x4 transposed convolutions with
  batch norm and ReLU mirroring the stages, a last transposed convolution with bias
  to the input's channels, sigmoid;
- regression head: ReLU, linear to 6, on the latent mean;
- loss: alpha/(1+alpha) * MSE(image) + 1/(1+alpha) * MSE(wrench) + beta * KL (closed
  form, mean over batch and latent), alpha 1, beta 0.1; Adam at 2e-3.

One step is what softtouch times: assemble a batch from the training set, draw the
latent noise, forward and loss (read back), backward, Adam. Images/s come from the
total time of the timed steps, as softtouch's. The training set is 2240 noise images
with standardised noise labels, as `bench train` uses without `--dataset`.

Unless `--skip-infer`, it also times the deployment path at batch 1 on one thread
(encoder -> mean -> head), with batch norm in evaluation mode and folded into the
convolutions.

Install and run (see bench/README.md):

    python3 -m venv .venv-torch && .venv-torch/bin/pip install torch numpy
    .venv-torch/bin/python bench/torch_peer.py --sizes 32,64 --widths 8,16 --train-threads 2
"""
import argparse
import json
import os
import sys
import time

import torch
from torch import nn
import torch.nn.functional as F

LOG_VAR_LIMIT = 30.0


def stage_channels(size_px, width):
    """Channels after the stem and after each residual stage (the trainer's rule)."""
    stages = max(size_px // 8, 1).bit_length() - 1
    return [width << min(i, 3) for i in range(stages + 1)]


def forward_macs_per_image(size_px, width, latent, channels_in=1):
    """Multiply-adds of one image through the training graph, and the stem's alone:
    a convolution's output elements x inputs per output, a transposed one's input
    elements x outputs per input (ModelConfig::forward_macs_per_image counts the same)."""
    ch = stage_channels(size_px, width)
    n = size_px // 2
    stem = n * n * ch[0] * channels_in * 9
    total = stem
    for a, b in zip(ch, ch[1:]):
        n //= 2
        total += n * n * b * (a * 9 + b * 9 + a)
    features = ch[-1] * 16
    total += 2 * features * latent + latent * 6 + latent * features
    n = 4
    for a, b in reversed(list(zip(ch, ch[1:]))):
        total += n * n * b * a * 16
        n *= 2
    total += n * n * ch[0] * channels_in * 16
    return total, stem


class ResBlock(nn.Module):
    def __init__(self, c_in, c_out, stride):
        super().__init__()
        self.conv1 = nn.Conv2d(c_in, c_out, 3, stride, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(c_out)
        self.conv2 = nn.Conv2d(c_out, c_out, 3, 1, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(c_out)
        self.skip = (
            nn.Conv2d(c_in, c_out, 1, stride) if stride != 1 or c_in != c_out else None
        )

    def forward(self, x):
        h = F.relu(self.bn1(self.conv1(x)))
        h = self.bn2(self.conv2(h))
        s = self.skip(x) if self.skip is not None else x
        return F.relu(h + s)


class Svae(nn.Module):
    def __init__(self, size_px, width, latent, channels_in=1):
        super().__init__()
        ch = stage_channels(size_px, width)
        self.top = ch[-1]
        features = self.top * 16
        self.stem = nn.Conv2d(channels_in, ch[0], 3, 2, 1, bias=False)
        self.stem_bn = nn.BatchNorm2d(ch[0])
        self.stages = nn.ModuleList(ResBlock(a, b, 2) for a, b in zip(ch, ch[1:]))
        self.fc_mean = nn.Linear(features, latent)
        self.fc_log_var = nn.Linear(features, latent)
        self.dec_fc = nn.Linear(latent, features)
        ups = []
        for a, b in reversed(list(zip(ch, ch[1:]))):
            ups += [nn.ConvTranspose2d(b, a, 4, 2, 1, bias=False), nn.BatchNorm2d(a), nn.ReLU()]
        self.ups = nn.Sequential(*ups)
        self.dec_out = nn.ConvTranspose2d(ch[0], channels_in, 4, 2, 1)
        self.head = nn.Linear(latent, 6)

    def encode(self, x):
        x = F.relu(self.stem_bn(self.stem(x)))
        for stage in self.stages:
            x = stage(x)
        return x.flatten(1)

    def forward(self, x, noise):
        features = self.encode(x)
        mean = self.fc_mean(features)
        log_var = self.fc_log_var(features).clamp(-LOG_VAR_LIMIT, LOG_VAR_LIMIT)
        wrench = self.head(F.relu(mean))
        z = mean + torch.exp(0.5 * log_var) * noise
        h = F.relu(self.dec_fc(z)).reshape(x.shape[0], self.top, 4, 4)
        image = torch.sigmoid(self.dec_out(self.ups(h)))
        return mean, log_var, wrench, image

    def forward_wrench(self, x):
        return self.head(F.relu(self.fc_mean(self.encode(x))))


def svae_loss(out, images, labels, alpha=1.0, beta=0.1):
    mean, log_var, wrench, image = out
    recon = F.mse_loss(image, images)
    pred = F.mse_loss(wrench, labels)
    kl = 0.5 * (mean.pow(2) + log_var.exp() - log_var - 1.0).mean()
    return alpha / (1 + alpha) * recon + 1 / (1 + alpha) * pred + beta * kl


def cpu_seconds():
    t = os.times()
    return t.user + t.system


def bench_train(args, size, width, device):
    torch.manual_seed(1)
    images = torch.rand(args.images, 1, size, size, device=device)
    labels = torch.randn(args.images, 6, device=device)
    net = Svae(size, width, args.latent).to(device)
    net.train()
    opt = torch.optim.Adam(net.parameters(), lr=2e-3)
    generator = torch.Generator(device="cpu").manual_seed(1)

    def step():
        index = torch.randint(0, args.images, (args.batch,), generator=generator).to(device)
        x, y = images[index], labels[index]
        noise = torch.randn(args.batch, args.latent, device=device)
        loss = svae_loss(net(x, noise), x, y)
        loss_value = loss.item()  # read back, as softtouch reads its loss every step
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        if device.type == "cuda":
            torch.cuda.synchronize()
        return loss_value

    for _ in range(args.warmup):
        step()
    cpu0, wall0 = cpu_seconds(), time.perf_counter()
    last = float("nan")
    for _ in range(args.steps):
        last = step()
    wall = time.perf_counter() - wall0
    cpu = cpu_seconds() - cpu0
    if not (last == last):  # NaN: the step is broken, the timing means nothing
        raise SystemExit(f"{size}x{size}/{width}: the loss is NaN")
    return net, wall, cpu, last


def fold_batch_norm(conv, bn):
    """A convolution with `bn` (evaluation mode) folded into its weights and bias."""
    folded = nn.Conv2d(conv.in_channels, conv.out_channels, conv.kernel_size,
                       conv.stride, conv.padding, bias=True)
    scale = bn.weight / torch.sqrt(bn.running_var + bn.eps)
    folded.weight.data = conv.weight.data * scale.reshape(-1, 1, 1, 1)
    bias = conv.bias.data if conv.bias is not None else torch.zeros_like(bn.running_mean)
    folded.bias.data = (bias - bn.running_mean) * scale + bn.bias.data
    return folded


class FoldedEncoder(nn.Module):
    """The deployment path with every batch norm folded into its convolution."""

    def __init__(self, net):
        super().__init__()
        self.stem = fold_batch_norm(net.stem, net.stem_bn)
        self.blocks = nn.ModuleList(
            nn.ModuleList([fold_batch_norm(b.conv1, b.bn1), fold_batch_norm(b.conv2, b.bn2), b.skip])
            for b in net.stages
        )
        self.fc_mean, self.head = net.fc_mean, net.head

    def forward(self, x):
        x = F.relu(self.stem(x))
        for conv1, conv2, skip in self.blocks:
            h = conv2(F.relu(conv1(x)))
            x = F.relu(h + (skip(x) if skip is not None else x))
        return self.head(F.relu(self.fc_mean(x.flatten(1))))


def latency_ms(fn, x, repeats):
    with torch.inference_mode():
        for _ in range(20):
            fn(x)
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn(x)
            times.append((time.perf_counter() - t0) * 1e3)
    times.sort()
    return times[len(times) // 2]


def parse_list(text, name):
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise SystemExit(f"--{name} {text!r}: expected comma-separated integers")
    if not values or any(v <= 0 for v in values):
        raise SystemExit(f"--{name} {text!r}: expected positive integers")
    return values


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--sizes", default="32", help="input sizes in px, e.g. 32,64")
    p.add_argument("--widths", default="16", help="stem widths, e.g. 8,16")
    p.add_argument("--latent", type=int, default=32)
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--warmup", type=int, default=5)
    p.add_argument("--steps", type=int, default=60)
    p.add_argument("--images", type=int, default=2240, help="training-set size")
    p.add_argument("--train-threads", type=int, default=2)
    p.add_argument("--device", default="cpu", help="cpu, or cuda where a GPU is lent")
    p.add_argument("--skip-infer", action="store_true", help="time training only")
    p.add_argument("--infer-repeats", type=int, default=300)
    args = p.parse_args()
    sizes, widths = parse_list(args.sizes, "sizes"), parse_list(args.widths, "widths")
    for name in ("latent", "batch", "steps", "images", "train_threads", "infer_repeats"):
        if getattr(args, name) <= 0:
            raise SystemExit(f"--{name.replace('_', '-')}: expected a positive integer")
    if args.warmup < 0:
        raise SystemExit("--warmup: expected 0 or more")
    for size in sizes:
        if size < 8 or size & (size - 1):
            raise SystemExit(f"--sizes {size}: expected a power of two, 8 or more")
    device = torch.device(args.device)
    for size in sizes:
        for width in widths:
            torch.set_num_threads(args.train_threads)
            net, wall, cpu, loss = bench_train(args, size, width, device)
            forward, stem = forward_macs_per_image(size, width, args.latent)
            gflop_per_image = 2.0 * (3 * forward - stem) / 1e9
            images_per_s = args.batch * args.steps / wall
            row = {
                "torch": torch.__version__,
                "device": str(device),
                "size": size,
                "width": width,
                "batch": args.batch,
                "steps": args.steps,
                "train_img_per_s_total": images_per_s,
                "train_cores_used": cpu / wall if device.type == "cpu" else None,
                "train_gflop_per_s": gflop_per_image * images_per_s,
                "fwd_macs_train_graph_per_img": forward,
                "stem_macs_per_img": stem,
                "last_loss": loss,
            }
            if not args.skip_infer:
                torch.set_num_threads(1)
                net = net.cpu().eval()
                x = torch.rand(1, 1, size, size)
                row["infer_ms_eval_bn"] = latency_ms(net.forward_wrench, x, args.infer_repeats)
                folded = FoldedEncoder(net).eval()
                with torch.inference_mode():
                    # Folding must not change the estimate, or its timing times another net.
                    torch.testing.assert_close(folded(x), net.forward_wrench(x), rtol=1e-4, atol=1e-4)
                row["infer_ms_folded_bn"] = latency_ms(folded, x, args.infer_repeats)
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    sys.exit(main())
