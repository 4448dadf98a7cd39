#!/usr/bin/env python3
"""Checks OpenTrackIO datagrams with decoders that are not previz's: the 16-byte header with the
SMPTE reference code (../shared/data/opentrackio/opentrackio_lib.py: its OTRK_* constants and
fletcher16), the payload with Debian's python3-jsonschema against the official schema.json
(1.0.1). Exit 1 on the first datagram that fails, or when jsonschema or the reference files are
missing (a missing validator must fail the test, never skip it).

  validate_opentrackio.py SHARED_OPENTRACKIO_DIR recording FILE.jsonl ...   (previz tracker recordings: "bytes" hex)
  validate_opentrackio.py SHARED_OPENTRACKIO_DIR listen PORT COUNT SECONDS OUT.hex   (UDP 127.0.0.1, writes one hex line a
      datagram; stops at COUNT datagrams, after SECONDS, or when OUT.hex.stop appears)
  validate_opentrackio.py SHARED_OPENTRACKIO_DIR hexfile FILE.hex ...

CBOR payloads are read with the small RFC 8949 reader below: the reference code needs the cbor2
package, which Debian 12 does not install with previz; when cbor2 is missing, a stand-in module
is put in its place so that the reference code imports (only its header pieces are used here).
"""
import json
import os
import socket
import struct
import sys
import time
import types

try:
    import jsonschema
except ImportError:
    print("FAIL: python3-jsonschema is not installed (scripts/setup.sh installs it)")
    sys.exit(1)


def load_reference(shared):
    sys.path.insert(0, shared)
    try:
        import cbor2  # noqa: F401
    except ImportError:
        stub = types.ModuleType("cbor2")
        def loads(_data):
            raise RuntimeError("cbor2 stand-in: CBOR is decoded by validate_opentrackio.py's reader")
        stub.loads = loads
        sys.modules["cbor2"] = stub
    import opentrackio_lib
    return opentrackio_lib


def cbor_decode(data):
    """Minimal RFC 8949 decoder: maps, arrays, text/byte strings, integers, floats, simple values."""
    def item(i):
        ib = data[i]
        major, info = ib >> 5, ib & 31
        i += 1
        if major == 7:
            if info == 20: return False, i
            if info == 21: return True, i
            if info == 22: return None, i
            if info == 25: return struct.unpack(">e", data[i:i + 2])[0], i + 2
            if info == 26: return struct.unpack(">f", data[i:i + 4])[0], i + 4
            if info == 27: return struct.unpack(">d", data[i:i + 8])[0], i + 8
            raise ValueError("cbor: simple value %d" % info)
        if info < 24: n = info
        elif info == 24: n, i = data[i], i + 1
        elif info == 25: n, i = struct.unpack(">H", data[i:i + 2])[0], i + 2
        elif info == 26: n, i = struct.unpack(">I", data[i:i + 4])[0], i + 4
        elif info == 27: n, i = struct.unpack(">Q", data[i:i + 8])[0], i + 8
        else: raise ValueError("cbor: indefinite lengths are not read here")
        if major == 0: return n, i
        if major == 1: return -1 - n, i
        if major == 2: return bytes(data[i:i + n]), i + n
        if major == 3: return data[i:i + n].decode("utf-8"), i + n
        if major == 4:
            out = []
            for _ in range(n):
                v, i = item(i)
                out.append(v)
            return out, i
        if major == 5:
            out = {}
            for _ in range(n):
                k, i = item(i)
                v, i = item(i)
                out[k] = v
            return out, i
        raise ValueError("cbor: major type %d" % major)
    value, end = item(0)
    if end != len(data):
        raise ValueError("cbor: %d bytes after the item" % (len(data) - end))
    return value


def check(lib, schema, d, where):
    """Header by the reference's layout and checksum, payload against the schema."""
    if len(d) < lib.OTRK_HEADER_LENGTH:
        return "%s: %d bytes, shorter than the header" % (where, len(d))
    if len(d) > lib.OTRK_MTU:
        return "%s: %d bytes, more than OTRK_MTU" % (where, len(d))
    if d[:lib.OTRK_IDENTIFIER_LENGTH] != lib.OTRK_IDENTIFIER:
        return "%s: identifier %r" % (where, d[:4])
    reserved, encoding, seq, offset, flag_len = struct.unpack("!BBHIH", d[4:14])
    last, length = flag_len >> 15, flag_len & 0x7FFF
    payload = d[lib.OTRK_HEADER_LENGTH:]
    if length != len(payload):
        return "%s: payload length %d in the header, %d sent" % (where, length, len(payload))
    if not last or offset != 0:
        return "%s: not a single-segment sample" % where
    if lib.fletcher16(d[:14] + payload) != d[14:16]:
        return "%s: checksum %s, the reference computes %s" % (where, d[14:16].hex(), lib.fletcher16(d[:14] + payload).hex())
    if encoding == lib.PayloadFormat.JSON.value:
        sample = json.loads(payload.decode("utf-8"))
    elif encoding == lib.PayloadFormat.CBOR.value:
        sample = cbor_decode(payload)
    else:
        return "%s: encoding %d" % (where, encoding)
    try:
        jsonschema.validate(instance=sample, schema=schema)
    except jsonschema.ValidationError as e:
        return "%s: schema: %s at %s" % (where, e.message, list(e.absolute_path))
    return None


def main():
    shared, mode, args = sys.argv[1], sys.argv[2], sys.argv[3:]
    lib = load_reference(shared)
    schema = json.load(open(os.path.join(shared, "schema.json")))
    datagrams = []
    if mode == "recording":
        for path in args:
            lines = [json.loads(l) for l in open(path) if l.strip()]
            assert lines[0]["format"] == "previz-tracker-recording", path
            datagrams += [(bytes.fromhex(l["bytes"]), "%s:%d" % (path, n + 2)) for n, l in enumerate(lines[1:])]
    elif mode == "hexfile":
        for path in args:
            datagrams += [(bytes.fromhex(l.strip()), "%s:%d" % (path, n + 1)) for n, l in enumerate(open(path)) if l.strip()]
    elif mode == "listen":
        port, count, seconds, out = int(args[0]), int(args[1]), float(args[2]), args[3]
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", port))
        s.settimeout(0.2)
        end = time.time() + seconds
        got = []
        open(out + ".ready", "w").close()
        # Ends at COUNT datagrams, after SECONDS, or once OUT.stop exists (and nothing is waiting).
        while time.time() < end and len(got) < count:
            if os.path.exists(out + ".stop"):
                s.settimeout(0.05)
                try:
                    got.append(s.recv(65536))
                    continue
                except socket.timeout:
                    break
            try:
                got.append(s.recv(65536))
            except socket.timeout:
                pass
        with open(out, "w") as f:
            for d in got:
                f.write(d.hex() + "\n")
        datagrams = [(d, "udp datagram %d" % n) for n, d in enumerate(got)]
    else:
        print("FAIL: unknown mode " + mode)
        return 1
    if not datagrams:
        print("FAIL: no datagram to check")
        return 1
    for d, where in datagrams:
        why = check(lib, schema, d, where)
        if why:
            print("FAIL: " + why)
            return 1
    print("ok: %d OpenTrackIO datagrams: header (SMPTE reference) and payload (schema %s) valid"
          % (len(datagrams), schema.get("$id", "")))
    return 0


if __name__ == "__main__":
    sys.exit(main())
