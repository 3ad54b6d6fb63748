"""Python OpenCV (cv2) baseline for the vision benchmark.

The Rust benchmark (`vision-bench`, `bench/vision/main.rs`) writes a JSON spec of the work to time, runs this script with
`opencv-python-headless<5`, and compares the per-call times it prints with its own, measured in the same run. Each
timed block makes the same OpenCV calls with the same parameters as the Rust detector it is compared with, on the
same decoded pixels, on one thread.

Usage: python cv2_baseline.py SPEC.json  ->  prints one JSON object {case: {"wall_ms": [...], "cpu_ms": [...]}}
"""

import json
import sys
import time

import cv2
import numpy as np


def timed(samples, fn):
    wall0, cpu0 = time.perf_counter(), time.thread_time()
    result = fn()
    samples["cpu_ms"].append((time.thread_time() - cpu0) * 1000.0)
    samples["wall_ms"].append((time.perf_counter() - wall0) * 1000.0)
    return result


def new_samples():
    return {"wall_ms": [], "cpu_ms": []}


def read_grey(path):
    data = np.fromfile(path, dtype=np.uint8)
    return cv2.imdecode(data, cv2.IMREAD_GRAYSCALE | cv2.IMREAD_IGNORE_ORIENTATION)


def bench_decode(spec, out):
    blobs = [np.fromfile(p, dtype=np.uint8) for p in spec["images"]]
    samples = new_samples()
    for _ in range(spec["rounds"]):
        for blob in blobs:
            timed(samples, lambda: cv2.imdecode(blob, cv2.IMREAD_GRAYSCALE | cv2.IMREAD_IGNORE_ORIENTATION))
    out["decode"] = samples


def bench_faces(spec, out):
    grey = read_grey(spec["image"])
    cascade = cv2.CascadeClassifier(spec["cascade"])
    if cascade.empty():
        raise SystemExit("cannot load cascade " + spec["cascade"])
    for case in spec["cases"]:
        samples = new_samples()
        width, height = case["detect_size"]
        min_size = tuple(case["min_size"])

        def run():
            image = grey
            if (width, height) != (grey.shape[1], grey.shape[0]):
                image = cv2.resize(grey, (width, height), interpolation=cv2.INTER_AREA)
            image = cv2.equalizeHist(image)
            return cascade.detectMultiScale(
                image, scaleFactor=case["scale_factor"], minNeighbors=case["min_neighbors"], minSize=min_size
            )

        for _ in range(spec["iterations"]):
            timed(samples, run)
        out["faces:" + case["name"]] = samples


def bench_centerface(spec, out):
    """One run of the CenterFace network as the Rust detector makes it: resize the grey frame to the input, grey to
    three channels, a float blob, the forward pass to the three maps it reads."""
    grey = read_grey(spec["image"])
    net = cv2.dnn.readNetFromONNX(spec["model"])
    width, height = spec["input"]
    samples = new_samples()

    def run():
        small = cv2.resize(grey, (width, height), interpolation=cv2.INTER_AREA)
        colour = cv2.cvtColor(small, cv2.COLOR_GRAY2BGR)
        blob = cv2.dnn.blobFromImage(colour, 1.0, (width, height), (0, 0, 0), False, False)
        net.setInput(blob)
        return net.forward(["537", "538", "539"])

    run()  # the first forward pass allocates the network's buffers
    for _ in range(spec["iterations"]):
        timed(samples, run)
    out["centerface"] = samples


def bench_motion(spec, out):
    frames = [read_grey(p) for p in spec["frames"]]
    width, height = spec["work_size"]
    open_kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
    merge_kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (9, 9))
    samples = new_samples()
    for _ in range(spec["rounds"]):
        previous = None
        for frame in frames:

            def run():
                nonlocal previous
                small = cv2.resize(frame, (width, height), interpolation=cv2.INTER_AREA)
                current = cv2.GaussianBlur(small, (5, 5), 0)
                if previous is None:
                    previous = current
                    return None
                diff = cv2.absdiff(previous, current)
                previous = current
                _, mask = cv2.threshold(diff, spec["pixel_threshold"], 255, cv2.THRESH_BINARY)
                cleaned = cv2.morphologyEx(mask, cv2.MORPH_OPEN, open_kernel)
                changed = cv2.countNonZero(cleaned) / float(width * height)
                if changed < spec["on_fraction"]:
                    return None
                cv2.moments(cleaned, True)
                merged = cv2.dilate(cleaned, merge_kernel, iterations=2)
                contours, _ = cv2.findContours(merged, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
                return [cv2.boundingRect(c) for c in contours]

            timed(samples, run)
    out["motion"] = samples


def bench_qr(spec, out):
    detector = cv2.QRCodeDetector()
    for name, paths in spec["sets"].items():
        images = [read_grey(p) for p in paths]
        samples = new_samples()
        decoded = []
        for _ in range(spec["rounds"]):
            for image in images:
                ok, texts, _, _ = timed(samples, lambda: detector.detectAndDecodeMulti(image))
                decoded.append(sum(1 for t in texts if t) if ok else 0)
        samples["decoded_per_frame"] = sum(decoded) / max(1, len(decoded))
        out["qr:" + name] = samples


def bench_barcode(spec, out):
    detector = cv2.barcode.BarcodeDetector()
    for name, paths in spec["sets"].items():
        images = [read_grey(p) for p in paths]
        samples = new_samples()
        for _ in range(spec["rounds"]):
            for image in images:
                timed(samples, lambda: detector.detectAndDecodeWithType(image))
        out["barcode:" + name] = samples


def main():
    with open(sys.argv[1], encoding="utf-8") as f:
        spec = json.load(f)
    cv2.setNumThreads(spec.get("threads", 1))
    out = {"cv2_version": cv2.__version__}
    for key, bench in (
        ("decode", bench_decode),
        ("faces", bench_faces),
        ("centerface", bench_centerface),
        ("motion", bench_motion),
        ("qr", bench_qr),
        ("barcode", bench_barcode),
    ):
        if key in spec:
            bench(spec[key], out)
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
