"""A cell's LCM log, read by the integration tests' checks.

LCM's log format: each event a 28-byte big-endian header (magic 0xEDA1DA01, event
number, utime, channel length, data length), then the channel and the data. A message's
data starts with LCM's 8-byte type fingerprint; the fields follow big-endian.
"""
import struct

MAGIC = 0xEDA1DA01


def events(path):
    """(utime, channel, data) of each whole event, in order; a torn last event ends it."""
    data = open(path, "rb").read()
    off = 0
    while off + 28 <= len(data):
        magic, _num, ts, clen, dlen = struct.unpack_from(">IqqII", data, off)
        if magic != MAGIC:
            raise ValueError(f"{path}: no event magic at byte {off}")
        end = off + 28 + clen + dlen
        if end > len(data):
            return
        yield ts, data[off + 28:off + 28 + clen].decode(), data[off + 28 + clen:end]
        off = end


def fields(payload, fmt):
    """The message's leading fields by struct format (big-endian, after the fingerprint)."""
    return struct.unpack_from(">" + fmt, payload, 8)


class Fields:
    """The message's fields one after another, strings included (int32 length with the NUL)."""

    def __init__(self, payload):
        self.b, self.p = payload, 8

    def get(self, fmt):
        v = struct.unpack_from(">" + fmt, self.b, self.p)
        self.p += struct.calcsize(">" + fmt)
        return v[0] if len(v) == 1 else v

    def str(self):
        n = self.get("i")
        v = self.b[self.p:self.p + n - 1].decode()
        self.p += n
        return v
