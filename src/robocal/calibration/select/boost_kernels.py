"""The compiled loop of :mod:`robocal.calibration.select.boosting` (the ``numba`` backend; imported only
when it runs).

One call grows all the trees of one output: scikit-learn's ``HistGradientBoostingRegressor`` with
squared loss, numerical features without missing values, no l2 regularisation, no depth limit and
the leaf and node limits given, done step by step as its Python grower and its Cython splitter do
them, so that the trees, their values and their predictions are the same to the last bit.  What
makes them so, and what a test against scikit-learn would catch if it changed:

- gradients are float32 (prediction − target), summed into float64 histograms sample by sample in
  the order of the node's samples (a stable partition keeps them in index order); the larger child's
  histogram is its parent's less the smaller child's, as the grower takes it;
- the root's sum of gradients is numpy's pairwise sum of its first feature's histogram
  (:func:`_pairwise`), its value 0 (so its gain is measured from 0), its hessians' sum n;
- a node's value is −G / (H + 1e-15) (l2 = 0), its split the first bin of the first feature of the
  greatest gain, with the grower's leaf, node and smallest-leaf rules, and the nodes waiting to be
  split in a binary heap run as Python's ``heapq`` runs it (ties pop as they would there);
- the learning rate multiplies the leaves once a tree is grown; the predictions add each tree's
  value to the last, tree after tree;
- early stopping compares the validation's mean half squared error (numpy's pairwise mean) with
  the one ``patience`` + 1 trees back (tolerance 0).

Where scikit-learn grows a tree in about 0.7 ms of Python, this grows one in about 0.1 ms: the
``auto`` ladder grows some fourteen thousand.  Compiling it takes about 8 s of a core (the
background compile after install; numba types one large loop).
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: numpy's pairwise summation block (``PW_BLOCKSIZE``)
_BLOCK = 128
#: the grower's smallest hessian sum a child may have (scikit-learn's ``min_hessian_to_split``)
_MIN_HESSIAN = 1e-3


@njit(cache=True, inline="always")
def _block(a, start, n):  # pragma: no cover
    """numpy's pairwise sum of a block of at most :data:`_BLOCK` values: eight partial sums."""
    if n < 8:
        res = 0.0
        for i in range(start, start + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[start], a[start + 1], a[start + 2], a[start + 3]
    r4, r5, r6, r7 = a[start + 4], a[start + 5], a[start + 6], a[start + 7]
    i = 8
    while i < n - (n % 8):
        b = start + i
        r0 += a[b]
        r1 += a[b + 1]
        r2 += a[b + 2]
        r3 += a[b + 3]
        r4 += a[b + 4]
        r5 += a[b + 5]
        r6 += a[b + 6]
        r7 += a[b + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[start + i]
        i += 1
    return res


@njit(cache=True)
def _pairwise(a, start, n):  # pragma: no cover
    """numpy's pairwise sum of a[start:start + n]: blocks of at most :data:`_BLOCK` values, halves
    (a multiple of eight first) summed above them.  Its recursion runs on a stack of its own: numba
    does not load a recursive function from its cache."""
    if n <= _BLOCK:
        return _block(a, start, n)
    s_start, s_n = np.empty(64, np.int64), np.empty(64, np.int64)
    s_phase, s_left = np.zeros(64, np.int64), np.empty(64)
    s_start[0], s_n[0], s_phase[0] = start, n, 0
    top, ret = 1, 0.0
    while top:
        k = top - 1
        m = s_n[k]
        if m <= _BLOCK:
            ret = _block(a, s_start[k], m)
            top -= 1
            continue
        half = m // 2
        half -= half % 8
        if s_phase[k] == 0:  # the first half
            s_phase[k] = 1
            s_start[top], s_n[top], s_phase[top] = s_start[k], half, 0
            top += 1
        elif s_phase[k] == 1:  # the second half
            s_left[k] = ret
            s_phase[k] = 2
            s_start[top], s_n[top], s_phase[top] = s_start[k] + half, m - half, 0
            top += 1
        else:
            ret = s_left[k] + ret
            top -= 1
    return ret


@njit(cache=True, inline="always")
def _sift_down(heap, gain, start, pos):  # pragma: no cover
    """heapq._siftdown, a node "less" than another when its gain is greater."""
    item = heap[pos]
    while pos > start:
        parent = (pos - 1) >> 1
        if gain[item] > gain[heap[parent]]:
            heap[pos] = heap[parent]
            pos = parent
            continue
        break
    heap[pos] = item


@njit(cache=True)
def _heap_pop(heap, size, gain):  # pragma: no cover
    """heapq.heappop of heap[:size]: the node of the greatest gain."""
    last = heap[size - 1]
    size -= 1
    if size == 0:
        return last
    top = heap[0]
    heap[0] = last
    pos, child = 0, 1  # heapq._siftup: the smaller child up to a leaf, then down again
    while child < size:
        right = child + 1
        if right < size and not gain[heap[child]] > gain[heap[right]]:
            child = right
        heap[pos] = heap[child]
        pos = child
        child = 2 * pos + 1
    heap[pos] = last
    _sift_down(heap, gain, 0, pos)
    return top


@njit(cache=True, inline="always")
def _brute(hg, hc, slot, Xb, part, start, stop, g):  # pragma: no cover
    """The histogram of the samples part[start:stop], in their order."""
    hg[slot] = 0.0
    hc[slot] = 0
    for f in range(Xb.shape[1]):
        sums, counts = hg[slot, f], hc[slot, f]
        for k in range(start, stop):
            i = part[k]
            b = Xb[i, f]
            sums[b] += g[i]
            counts[b] += 1


@njit(cache=True)
def _best_split(hg, hc, slot, nbins, n, sum_g, sum_h, value, min_leaf, out):  # pragma: no cover
    """The splitter's best split of a node (scikit-learn's ``find_node_split``, left to right):
    out = (gain, feature, bin, G left, H left, n left, value left, value right); gain −1: none."""
    out[0] = -1.0
    out[1] = 0.0
    loss = sum_g * value
    for f in range(hg.shape[1]):
        best, found = -1.0, False
        bb, bg, bh, bn = 0, 0.0, 0.0, 0
        gl, hl, nl = 0.0, 0.0, 0
        sums, counts = hg[slot, f], hc[slot, f]
        for b in range(nbins[f] - 1):
            c = counts[b]
            if c == 0:  # an empty bin: the same sums and gain as the bin before, which a strict > never takes
                continue
            nl += c
            nr = n - nl
            hl += c
            hr = sum_h - hl
            gl += sums[b]
            gr = sum_g - gl
            if nl < min_leaf:
                continue
            if nr < min_leaf:
                break
            if hl < _MIN_HESSIAN:
                continue
            if hr < _MIN_HESSIAN:
                break
            gain = loss
            gain -= gl * (-gl / (hl + 1e-15))
            gain -= gr * (-gr / (hr + 1e-15))
            if gain > best and gain > 0.0:
                best, found = gain, True
                bb, bg, bh, bn = b, gl, hl, nl
        if found and best > out[0]:  # the first feature of the greatest gain
            gr, hr = sum_g - bg, sum_h - bh
            out[0], out[1], out[2], out[3], out[4], out[5] = best, f, bb, bg, bh, bn
            out[6] = -bg / (bh + 1e-15)
            out[7] = -gr / (hr + 1e-15)


@njit(cache=True)
def _walk(feature, bin_, left, right, value, root, Xb, out):  # pragma: no cover
    """out[i] += the tree's leaf value at binned sample i (left where its bin ≤ the node's)."""
    for i in range(Xb.shape[0]):
        node = root
        while feature[node] >= 0:
            node = left[node] if Xb[i, feature[node]] <= bin_[node] else right[node]
        out[i] += value[node]


@njit(cache=True)
def _grow_one(Xb, g, nbins, min_leaf, max_leaf, hg, hc, part, buf, start, stop, sg, sh, val, leaf, kids, split, heap,
              gain):  # pragma: no cover
    """One tree grown on the gradients g, scikit-learn's grower's way (the module docstring): its nodes
    in the arrays given (children in ``kids``, leaves marked in ``leaf``, each node's samples
    part[start:stop]); a node's number is its order of creation, the root 0."""
    n, F = Xb.shape
    B = hg.shape[2]
    for i in range(n):
        part[i] = i
    # the root
    nodes, finalized, size = 1, 0, 0
    start[0], stop[0] = 0, n
    _brute(hg, hc, 0, Xb, part, 0, n, g)
    sg[0] = _pairwise(hg[0, 0], 0, B)
    sh[0] = float(n)
    val[0] = 0.0
    leaf[0] = False
    gain[0] = -1.0
    if n < 2 * min_leaf or sh[0] < _MIN_HESSIAN:
        leaf[0] = True
        finalized += 1
    else:
        _best_split(hg, hc, 0, nbins, n, sg[0], sh[0], val[0], min_leaf, split[0])
        gain[0] = split[0, 0]
        if gain[0] <= 0.0:
            leaf[0] = True
            finalized += 1
        else:
            heap[0] = 0
            size = 1
    while size:
        node = _heap_pop(heap, size, gain)
        size -= 1
        f, b = int(split[node, 1]), int(split[node, 2])
        s0, s1 = start[node], stop[node]
        nl, nr = s0, 0  # a stable partition: the left samples first, each side in its order
        for k in range(s0, s1):
            i = part[k]
            if Xb[i, f] <= b:
                part[nl] = i
                nl += 1
            else:
                buf[nr] = i
                nr += 1
        for k in range(nr):
            part[nl + k] = buf[k]
        L, R = nodes, nodes + 1
        nodes += 2
        kids[node, 0], kids[node, 1] = L, R
        start[L], stop[L], start[R], stop[R] = s0, nl, nl, s1
        sg[L], sh[L], val[L] = split[node, 3], split[node, 4], split[node, 6]
        sg[R], sh[R], val[R] = sg[node] - split[node, 3], sh[node] - split[node, 4], split[node, 7]
        leaf[L] = leaf[R] = False
        gain[L] = gain[R] = -1.0
        if finalized + size + 2 == max_leaf:
            leaf[L] = leaf[R] = True
            for k in range(size):
                leaf[heap[k]] = True
            finalized += 2 + size
            size = 0
            break
        nL, nR = nl - s0, s1 - nl
        if nL < 2 * min_leaf:
            leaf[L] = True
            finalized += 1
        if nR < 2 * min_leaf:
            leaf[R] = True
            finalized += 1
        if not (leaf[L] and leaf[R]):
            small, large = (L, R) if nL < nR else (R, L)
            _brute(hg, hc, small, Xb, part, start[small], stop[small], g)
            for ff in range(F):
                for bb in range(B):
                    hg[large, ff, bb] = hg[node, ff, bb] - hg[small, ff, bb]
                    hc[large, ff, bb] = hc[node, ff, bb] - hc[small, ff, bb]
            for child in (L, R):
                if not leaf[child]:
                    _best_split(hg, hc, child, nbins, stop[child] - start[child], sg[child], sh[child],
                                val[child], min_leaf, split[child])
                    gain[child] = split[child, 0]
                    if gain[child] <= 0.0:
                        leaf[child] = True
                        finalized += 1
                    else:
                        heap[size] = child
                        size += 1
                        _sift_down(heap, gain, 0, size - 1)


@njit(cache=True)
def _lay_out(leaf, kids, split, gain, val, start, stop, part, learning_rate, used, raw, order, stack, o_feature, o_bin,
             o_left, o_right, o_value, o_gain):  # pragma: no cover
    """The grown tree's nodes written from ``used`` on in scikit-learn's predictor order (depth first,
    left before right), its leaves shrunk by the learning rate and added to the training predictions
    raw; how many nodes it has."""
    # the leaves shrunk, the training predictions moved; the nodes laid out depth first
    top, count = 0, 0
    stack[0] = 0
    top = 1
    while top:
        top -= 1
        node = stack[top]
        order[count] = node
        count += 1
        if not leaf[node]:
            stack[top] = kids[node, 1]
            stack[top + 1] = kids[node, 0]
            top += 2
    where = np.empty(len(leaf), np.int64)
    for k in range(count):
        where[order[k]] = used + k
    for k in range(count):
        node = order[k]
        j = used + k
        o_gain[j] = gain[node]
        if leaf[node]:
            v = val[node] * learning_rate
            o_feature[j], o_bin[j], o_left[j], o_right[j], o_value[j] = -1, 0, -1, -1, v
            for kk in range(start[node], stop[node]):
                raw[part[kk]] += v
        else:
            o_feature[j], o_bin[j] = int(split[node, 1]), int(split[node, 2])
            o_left[j], o_right[j], o_value[j] = where[kids[node, 0]], where[kids[node, 1]], 0.0
    return count


@njit(cache=True)
def grow_trees(Xb, y, nbins, baseline, learning_rate, max_iter, max_leaf, min_leaf, Xv, yv, patience,
               Xt, yt, check_at, check_patience):  # pragma: no cover
    """Boost up to ``max_iter`` trees on the binned samples Xb (n, F) uint8 and targets y (n,).

    nbins (F,): each feature's bins with values; Xv, yv: the binned validation samples and targets of
    early stopping (none when Xv has no rows); Xt (m, F): binned samples whose prediction after each
    tree is wanted, and yt their targets: after ``check_at`` trees (0: never), growing stops where the
    last of them lies more than ``check_patience`` trees past the least squared error at Xt.  Returns
    the trees' nodes in scikit-learn's predictor order (each tree's nodes depth first, left before
    right): feature (−1 at a leaf), bin, left, right (absolute, −1 at a leaf), value (leaves, learning
    rate included), gain (the split's; −1 where none), the roots, and the predictions at Xt after each
    tree (trees, m)."""
    n, F = Xb.shape
    B = 256  # the histograms' bins: 255 for values and one for missing ones, as scikit-learn keeps them
    M = 2 * max_leaf - 1
    hg = np.zeros((M, F, B))
    hc = np.zeros((M, F, B), dtype=np.int32)
    part = np.arange(n)
    buf = np.empty(n, dtype=np.int64)
    start, stop = np.empty(M, np.int64), np.empty(M, np.int64)
    sg, sh, val = np.empty(M), np.empty(M), np.empty(M)
    leaf = np.zeros(M, np.bool_)
    kids = np.empty((M, 2), np.int64)
    split = np.empty((M, 8))
    heap = np.empty(M, np.int64)
    gain = np.empty(M)
    order = np.empty(M, np.int64)
    stack = np.empty(M, np.int64)
    g = np.empty(n, np.float32)
    raw = np.full(n, baseline)
    raw_v = np.full(Xv.shape[0], baseline)
    raw_t = np.full(Xt.shape[0], baseline)
    loss_v = np.empty(Xv.shape[0])
    scores = np.empty(max_iter + 1)
    staged = np.empty((max_iter, Xt.shape[0]))
    cap = max_iter * M
    o_feature, o_bin = np.empty(cap, np.int64), np.empty(cap, np.int64)
    o_left, o_right = np.empty(cap, np.int64), np.empty(cap, np.int64)
    o_value, o_gain = np.empty(cap), np.empty(cap)
    roots = np.empty(max_iter, np.int64)
    used = 0
    if Xv.shape[0]:
        for i in range(Xv.shape[0]):
            loss_v[i] = 0.5 * (raw_v[i] - yv[i]) * (raw_v[i] - yv[i])
        scores[0] = -(_pairwise(loss_v, 0, Xv.shape[0]) / Xv.shape[0])
    trees = 0
    for it in range(max_iter):
        for i in range(n):
            g[i] = raw[i] - y[i]
        _grow_one(Xb, g, nbins, min_leaf, max_leaf, hg, hc, part, buf, start, stop, sg, sh, val, leaf, kids, split,
                  heap, gain)
        roots[it] = used
        count = _lay_out(leaf, kids, split, gain, val, start, stop, part, learning_rate, used, raw, order, stack,
                         o_feature, o_bin, o_left, o_right, o_value, o_gain)
        used += count
        trees = it + 1
        if Xt.shape[0]:
            _walk(o_feature, o_bin, o_left, o_right, o_value, roots[it], Xt, raw_t)
            staged[it] = raw_t
            if trees == check_at and check_at < max_iter:
                least, at = np.inf, 0
                sq = np.empty(Xt.shape[0])
                for t in range(trees):  # numpy's sum over each row of (staged − yt)², its first least
                    for i in range(Xt.shape[0]):
                        d = staged[t, i] - yt[i]
                        sq[i] = d * d
                    total = _pairwise(sq, 0, Xt.shape[0])
                    if total < least:
                        least, at = total, t
                if trees - at > check_patience:
                    break
        if Xv.shape[0]:
            _walk(o_feature, o_bin, o_left, o_right, o_value, roots[it], Xv, raw_v)
            for i in range(Xv.shape[0]):
                loss_v[i] = 0.5 * (raw_v[i] - yv[i]) * (raw_v[i] - yv[i])
            scores[trees] = -(_pairwise(loss_v, 0, Xv.shape[0]) / Xv.shape[0])
            if trees + 1 >= patience + 1:  # none of the last `patience` better than the one before them
                reference = scores[trees - patience]
                better = False
                for k in range(trees - patience + 1, trees + 1):
                    if scores[k] > reference:
                        better = True
                if not better:
                    break
    return (o_feature[:used].copy(), o_bin[:used].copy(), o_left[:used].copy(), o_right[:used].copy(),
            o_value[:used].copy(), o_gain[:used].copy(), roots[:trees].copy(), staged[:trees].copy())
