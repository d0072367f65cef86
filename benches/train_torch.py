"""PyTorch baseline for `facelab bench train` (issue 4): the same network (17 -> 4 x 100 ReLU
-> 56), optimizer (Adam, lr 0.01), batch size (32), epochs (100) and data, one thread.

    facelab bench train --export /tmp/pairs.csv     # prints train.unified <seconds> s
    python3 benches/train_torch.py /tmp/pairs.csv   # prints torch.unified <seconds> s

Times the training loop only, as the facelab bench does (data already in memory).
"""
import sys
import time

import numpy as np
import torch

torch.set_num_threads(1)
torch.manual_seed(1)
data = np.loadtxt(sys.argv[1], delimiter=",", dtype=np.float32)
x = torch.from_numpy(data[:, :17].copy())
y = torch.from_numpy(data[:, 17:].copy())
layers = []
width = 17
for _ in range(4):
    layers += [torch.nn.Linear(width, 100), torch.nn.ReLU()]
    width = 100
layers.append(torch.nn.Linear(width, 56))
net = torch.nn.Sequential(*layers)
opt = torch.optim.Adam(net.parameters(), lr=0.01)
loss_fn = torch.nn.MSELoss()
n = x.shape[0]
start = time.perf_counter()
for epoch in range(int(sys.argv[2]) if len(sys.argv) > 2 else 100):
    order = torch.randperm(n)
    for i in range(0, n, 32):
        idx = order[i : i + 32]
        opt.zero_grad()
        loss = loss_fn(net(x[idx]), y[idx])
        loss.backward()
        opt.step()
print(f"torch.unified {time.perf_counter() - start:.4f} s")
print(f"torch.final_batch_mse {loss.item():.6f} mse")
