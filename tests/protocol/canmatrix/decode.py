#!/usr/bin/python3
"""Decodes frames with Debian's python3-canmatrix (an independent DBC decoder) for pumptherm's
cross-check test (tests/protocol/codec_canmatrix_test.cpp).

    /usr/bin/python3 decode.py FILE.dbc FRAMES.txt [FILE2.dbc FRAMES2.txt ...]

Pairs of files are decoded in one process (importing canmatrix takes most of a second).
FRAMES.txt: one frame per line, "<CAN ID hex> <extended 0|1> <payload hex>". Output: for each
pair "file <pair index>", then one line per signal canmatrix decodes (multiplexed signals that
the frame does not select are left out):
    sig <frame index> <signal name> <raw> <physical>
"msg <frame index> <message name>" for each frame it knows, "nomsg <frame index>" for a frame
whose ID canmatrix did not load, and "padded <frame index>"
for a frame canmatrix could not decode at its declared length (a signal reaching past it),
decoded again padded with zeros to 64 bytes. Numbers are printed with repr (shortest round trip).
"""
import sys
import logging

import canmatrix.formats


def decode_file(dbc_path, frames_path, out):
    db = canmatrix.formats.loadp_flat(dbc_path)
    with open(frames_path) as frames:
        for index, line in enumerate(frames):
            fields = line.split()
            if not fields:
                continue
            arb = canmatrix.ArbitrationId(id=int(fields[0], 16), extended=fields[1] == "1")
            frame = db.frame_by_id(arb)
            if frame is None:
                out.append("nomsg %d" % index)
                continue
            out.append("msg %d %s" % (index, frame.name))
            payload = bytearray.fromhex(fields[2] if len(fields) > 2 else "")
            try:
                decoded_signals = frame.decode(payload)
            except (canmatrix.canmatrix.DecodingFrameLength, ValueError):
                # A signal reaching past the declared length: canmatrix refuses the frame or
                # fails on the missing bits. Decoded again as a 64-byte frame, the rest zeros.
                out.append("padded %d" % index)
                frame.size = 64
                decoded_signals = frame.decode(payload + bytearray(64 - len(payload)))
            for name, decoded in decoded_signals.items():
                out.append("sig %d %s %r %r" % (index, name, decoded.raw_value, float(decoded.phys_value)))


def main():
    args = sys.argv[1:]
    if not args or len(args) % 2 != 0:
        sys.stderr.write("usage: decode.py FILE.dbc FRAMES.txt [FILE2.dbc FRAMES2.txt ...]\n")
        sys.exit(2)
    logging.disable(logging.CRITICAL)  # canmatrix logs each line it cannot read
    results = sys.stdout
    sys.stdout = sys.stderr  # and prints them too
    out = []
    for pair in range(len(args) // 2):
        out.append("file %d" % pair)
        decode_file(args[2 * pair], args[2 * pair + 1], out)
    results.write("\n".join(out) + "\n")


main()
