"""Draws the soak's CSV (bench/soak/main.rs --write) as one PNG: RSS and open descriptors per process by minute,
and every turn's voice-to-voice time, so that a leak or a slowdown shows as a slope."""

import argparse
import csv


def read(path):
    samples, turns = [], []
    with open(path, newline="") as f:
        block = samples
        for row in csv.reader(f):
            if not row:
                continue
            if row[0] == "turn_s":
                block = turns
                continue
            block.append(row)
    return samples, turns


def main(csv_path, png_path):
    # Imported here, so that --help answers without matplotlib (it is in bench/soak/.venv, `make soak`).
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    samples, turns = read(csv_path)
    head, rows = samples[0], samples[1:]
    minutes = [int(r[0]) for r in rows]
    names = [h[: -len("_rss_mib")] for h in head if h.endswith("_rss_mib")]
    fig, (rss, fds, v2v) = plt.subplots(3, 1, figsize=(9, 9), sharex=False)
    for name in names:
        col = head.index(name + "_rss_mib")
        rss.plot(minutes, [float(r[col]) for r in rows], marker=".", label=name)
        col = head.index(name + "_fds")
        fds.plot(minutes, [int(r[col]) for r in rows], marker=".", label=name)
    rss.set_ylabel("RSS (MiB)")
    rss.legend(loc="upper left", fontsize="small")
    fds.set_ylabel("open descriptors")
    fds.set_xlabel("minute")
    at = [int(t[0]) / 60 for t in turns]
    ms = [float(t[1]) for t in turns]
    v2v.plot(at, ms, ".", color="tab:red")
    v2v.set_ylabel("voice to voice (ms)")
    v2v.set_xlabel("minute")
    fig.suptitle("soak: " + ", ".join(names))
    fig.tight_layout()
    fig.savefig(png_path, dpi=90)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("csv", help="the soak's CSV (written beside its --write report)")
    ap.add_argument("png", help="the PNG to draw")
    args = ap.parse_args()
    main(args.csv, args.png)
