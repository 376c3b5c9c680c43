#!/usr/bin/env python3
"""tesserad and tessera work with MemoryDenyWriteExecute=yes, as the systemd unit sets it.

systemd implements MemoryDenyWriteExecute with a seccomp filter; Linux 6.3+ has the same rule as a process flag,
prctl(PR_SET_MDWE, PR_MDWE_REFUSE_EXEC_GAIN), kept across fork and execve. This test sets it in the child before
exec and then: renders the Cornell box locally with `tessera render` (Embree, TBB, OpenImageIO writing PNG and EXR),
and starts `tesserad` on an ephemeral loopback port, renders a job over HTTP, fetches its PNG and stops it with
SIGTERM. Any library that made a page writable and executable (a JIT) would crash or fail here.

    mdwe_test.py SOURCE_DIR TESSERAD TESSERA
Exit 0 passed, 1 failed, 77 skipped (a kernel without PR_SET_MDWE).
"""
import ctypes
import json
import mmap
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
import urllib.request

PR_SET_MDWE, PR_MDWE_REFUSE_EXEC_GAIN = 65, 1
src, tesserad, tessera = sys.argv[1:4]
libc = ctypes.CDLL(None, use_errno=True)


def set_mdwe():
    if libc.prctl(PR_SET_MDWE, PR_MDWE_REFUSE_EXEC_GAIN, 0, 0, 0) != 0:
        raise OSError(ctypes.get_errno(), "prctl(PR_SET_MDWE)")


# Does this kernel have it? Try in a child, and check that the rule bites there.
probe = subprocess.run(
    [sys.executable, "-c",
     "import mmap\ntry:\n mmap.mmap(-1, 4096, prot=7)\n print('allowed')\nexcept OSError:\n print('refused')"],
    preexec_fn=set_mdwe, capture_output=True, text=True) if hasattr(os, "fork") else None
if probe is None or probe.returncode != 0:
    print(f"SKIPPED: this kernel has no PR_SET_MDWE ({os.uname().release}): {probe.stderr.strip()[-200:] if probe else ''}")
    sys.exit(77)
if probe.stdout.strip() != "refused":
    print("FAIL: PR_SET_MDWE is set but a writable+executable mapping is still allowed")
    sys.exit(1)
print("ok   PR_SET_MDWE refuses writable+executable memory in the child")

failed = False
job = json.load(open(os.path.join(src, "proto", "examples", "cornell.json")))
job.setdefault("render", {}).update(width=48, height=48, spp=8)

with tempfile.TemporaryDirectory() as tmp:
    job_path = os.path.join(tmp, "job.json")
    json.dump(job, open(job_path, "w"))

    out_png, out_exr = os.path.join(tmp, "local.png"), os.path.join(tmp, "local.exr")
    r = subprocess.run([tessera, "render", job_path, "-o", out_png, "-o", out_exr, "-q"], preexec_fn=set_mdwe,
                       capture_output=True, text=True, timeout=300)
    ok = r.returncode == 0 and os.path.getsize(out_png) > 100 and os.path.getsize(out_exr) > 100
    print(("ok   " if ok else "FAIL ") + f"tessera render under MDWE (status {r.returncode}) {r.stderr.strip()[-300:]}")
    failed |= not ok

    data_dir = os.path.join(tmp, "data")
    daemon = subprocess.Popen([tesserad, "--listen", "127.0.0.1", "--port", "0", "--data-dir", data_dir,
                               "--threads", "2"], preexec_fn=set_mdwe, stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL, text=True)
    try:
        line = daemon.stdout.readline()
        m = re.match(r"listening on (http://\S+)", line)
        if not m:
            raise RuntimeError(f"tesserad under MDWE did not start: {line!r}, status {daemon.poll()}")
        url = m.group(1)
        req = urllib.request.Request(url + "/v1/jobs", data=json.dumps(job).encode(),
                                     headers={"Content-Type": "application/json"}, method="POST")
        job_id = json.load(urllib.request.urlopen(req, timeout=30))["id"]
        deadline = time.time() + 300
        while True:
            state = json.load(urllib.request.urlopen(f"{url}/v1/jobs/{job_id}", timeout=10))["state"]
            if state in ("succeeded", "failed", "cancelled") or time.time() > deadline:
                break
            time.sleep(0.2)
        png = urllib.request.urlopen(f"{url}/v1/jobs/{job_id}/result.png", timeout=30).read() \
            if state == "succeeded" else b""
        ok = state == "succeeded" and png[:8] == b"\x89PNG\r\n\x1a\n"
        print(("ok   " if ok else "FAIL ") + f"tesserad under MDWE rendered a job over HTTP ({state}, {len(png)} bytes)")
        failed |= not ok
    except Exception as e:  # noqa: BLE001 - any failure of the daemon is the test's failure
        print(f"FAIL tesserad under MDWE: {e}")
        failed = True
    finally:
        daemon.send_signal(signal.SIGTERM)
        try:
            status = daemon.wait(timeout=30)
        except subprocess.TimeoutExpired:
            daemon.kill()
            status = "killed after 30 s"
    ok = status == 0
    print(("ok   " if ok else "FAIL ") + f"tesserad under MDWE stops on SIGTERM with status {status}")
    failed |= not ok

sys.exit(1 if failed else 0)
