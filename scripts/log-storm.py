#!/usr/bin/env python3
"""Hammer a jointd whose bus `x` is down, to measure log volume: log-storm.py PORT [SECONDS]."""
import sys, threading, time, urllib.request
port = sys.argv[1]; secs = float(sys.argv[2]) if len(sys.argv) > 2 else 6
base = f"http://127.0.0.1:{port}/api/v1"
n = [0]; stop = time.time() + secs
def worker(i):
    while time.time() < stop:
        if i % 3 == 1:
            req = urllib.request.Request(base + "/buses/x/devices/1/enable", method="POST", data=b"")
        elif i % 3 == 2:
            req = urllib.request.Request(base + "/buses/x/estop", method="POST", data=b"{}", headers={"content-type": "application/json"})
        else:
            req = urllib.request.Request(base + "/buses/x/devices/1")
        try: urllib.request.urlopen(req, timeout=2).read()
        except Exception: pass
        n[0] += 1
ts = [threading.Thread(target=worker, args=(i,)) for i in range(8)]
[t.start() for t in ts]; [t.join() for t in ts]
print("requests", n[0])
