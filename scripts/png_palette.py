"""Re-encode an 8-bit RGB(A) PNG as an indexed-colour PNG, zlib level 9 (lossless up to 256
colours; beyond, the rarest go to the nearest kept colour). Pure standard library."""
import struct, sys, zlib

def chunks(data):
    i = 8
    while i < len(data):
        n, = struct.unpack(">I", data[i:i+4]); t = data[i+4:i+8]
        yield t, data[i+8:i+8+n]; i += 12 + n

def unfilter(raw, w, h, bpp):
    stride = w * bpp; out = bytearray(); prev = bytearray(stride); i = 0
    for _ in range(h):
        f = raw[i]; line = bytearray(raw[i+1:i+1+stride]); i += 1 + stride
        for x in range(stride):
            a = line[x-bpp] if x >= bpp else 0; b = prev[x]; c = prev[x-bpp] if x >= bpp else 0
            if f == 1: line[x] = (line[x] + a) & 255
            elif f == 2: line[x] = (line[x] + b) & 255
            elif f == 3: line[x] = (line[x] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c; pa, pb, pc = abs(p-a), abs(p-b), abs(p-c)
                line[x] = (line[x] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        out += line; prev = line
    return out

src, dst = sys.argv[1], sys.argv[2]
data = open(src, "rb").read()
idat = b""; 
for t, d in chunks(data):
    if t == b"IHDR": w, h, depth, ctype = struct.unpack(">IIBB", d[:10])
    elif t == b"IDAT": idat += d
assert depth == 8 and ctype in (2, 6), (depth, ctype)
bpp = 3 if ctype == 2 else 4
px = unfilter(zlib.decompress(idat), w, h, bpp)
from collections import Counter
count = Counter(bytes(px[o:o+3]) for o in range(0, w*h*bpp, bpp))
keep = [c for c, _ in count.most_common(256)]
index = {c: i for i, c in enumerate(keep)}
def nearest(c):
    return min(range(len(keep)), key=lambda i: sum((a-b)**2 for a, b in zip(c, keep[i])))
for c in count:
    if c not in index: index[c] = nearest(c)
moved = sum(n for c, n in count.items() if keep[index[c]] != c)
rows = bytearray()
for y in range(h):
    rows.append(0)
    for x in range(w):
        o = (y*w + x) * bpp; rows.append(index[bytes(px[o:o+3])])
colours = {c: i for i, c in enumerate(keep)}
def chunk(t, d): return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
pal = b"".join(sorted(colours, key=colours.get))
out = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 3, 0, 0, 0)) + chunk(b"PLTE", pal) + chunk(b"IDAT", zlib.compress(bytes(rows), 9)) + chunk(b"IEND", b"")
open(dst, "wb").write(out)
print(f"{len(count)} colours ({moved} pixels moved to the nearest of the 256 most used), {len(data)} -> {len(out)} octets")
