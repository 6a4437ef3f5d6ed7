#!/usr/bin/env python3
"""Writes the seed corpora under fuzz/corpus/<target>/ (committed; rerun after changing).

Seeds are the protocol README's examples, the scenes/ files, hand-written volume headers
and a few inputs aimed at known edges (non-ASCII and cut UTF-8, "..", links). No real
scan data. Each seed's file name says what it is. libFuzzer adds what it finds to a
scratch folder, never here.
"""
import gzip
import json
import pathlib
import re
import struct

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent
CORPUS = HERE / "corpus"


def write(target, name, data):
    folder = CORPUS / target
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_bytes(data if isinstance(data, bytes) else data.encode())


def readme_lines(prefix):
    text = (ROOT / "protocol" / "README.md").read_text()
    return [m.group(1) for m in re.finditer(r"^" + prefix + r": (\{.*\})$", text, re.M)]


def client_messages():
    for i, line in enumerate(readme_lines("C")):
        write("fuzz_client_message", f"readme_{i:02}.json", line)
    # Non-ASCII: whole and cut UTF-8 sequences (a cut one once crashed the server).
    write("fuzz_client_message", "utf8_name.json", '{"type": "open_volume", "id": 1, "name": "sch\u00e4del/\u8133.nrrd"}')
    write("fuzz_client_message", "utf8_cut_in_string.json", b'{"type": "hello", "id": 1, "protocol": 1, "client": "\xc3"}')
    write("fuzz_client_message", "utf8_cut_at_end.txt", b'{"type": "hello", "client": "\xe8\x84')
    write("fuzz_client_message", "latin1_type.json", b'{"type": "h\xe9llo"}')
    write("fuzz_client_message", "string_id.json", '{"type": "get_state", "id": "r\u00e9q-1"}')
    write("fuzz_client_message", "quality_automatic.json",
          '{"type": "quality_policy", "id": 20, "mode": "automatic", "target_frame_ms": 60, "quality": null}')
    write("fuzz_client_message", "still_null.json", '{"type": "still", "id": 21, "image": null}')
    write("fuzz_client_message", "hello_token.json", '{"type": "hello", "id": 0, "protocol": 1, "token": "s3cr\u00eat", "client": "x"}')


def server_messages():
    for i, line in enumerate(readme_lines("S")):
        write("fuzz_server_message", f"readme_{i:02}.json", line)
    write("fuzz_server_message", "error_utf8.json",
          '{"type": "error", "id": "\u00e9", "code": "not_found", "message": "volume \\"\u8133\\" not found", "request_type": "open_volume"}')
    write("fuzz_server_message", "error_unknown_code.json",
          '{"type": "error", "id": null, "code": "from_the_future", "message": "x", "request_type": null}')


def frame(header, image):
    text = json.dumps(header, separators=(",", ":"), ensure_ascii=False).encode()
    return b"VCF1" + struct.pack("<I", len(text)) + text + image


def frames():
    image = bytes(range(16))
    base = {"seq": 1, "request": 7, "level": 0, "quality": {"step": 0.5, "interpolation": "linear"},
            "width": 4, "height": 2, "codec": "jpeg", "render_ms": 12.5, "encode_ms": 1.25,
            "error": None, "final": False, "camera": None, "image_bytes": len(image)}
    write("fuzz_frame", "jpeg_level0.bin", frame(base, image))
    final = dict(base, seq=9, request="r\u00e9q", level=2, codec="png", final=True,
                 error={"value": 0.0042, "method": "rmse_vs_next_level"},
                 camera={"eye": [600, 500, 700], "target": [127.5, 127.5, 127.5], "up": [0, 1, 0],
                         "projection": "perspective", "fov_y_deg": 30})
    write("fuzz_frame", "png_final_error_camera.bin", frame(final, image))
    write("fuzz_frame", "no_image.bin", frame(dict(base, image_bytes=0), b""))
    write("fuzz_frame", "truncated.bin", frame(base, image)[:-3])
    write("fuzz_frame", "wrong_magic.bin", b"VCF2" + frame(base, image)[4:])
    # A level of fewer rays, sent at its grid's size with the view's beside it; a view smaller
    # than its image (refused).
    write("fuzz_frame", "scaled_view.bin", frame(dict(base, width=2, height=1, view_width=4, view_height=2), image))
    write("fuzz_frame", "view_smaller_than_image.bin", frame(dict(base, view_width=3, view_height=2), image))
    # A pass of refinement at rest after the final frame; a pass number past the limit (refused).
    write("fuzz_frame", "rest_pass.bin", frame(dict(base, codec="png", rest_pass=2,
                                                    error={"value": 5.6e-4, "method": "rmse_vs_previous_pass_over_3"}), image))
    write("fuzz_frame", "rest_pass_too_large.bin", frame(dict(base, rest_pass=65), image))


def volume_names():
    names = ["bonsai", "ct/head.nrrd", "../secrets/key.nrrd", "/etc/passwd", "C:/scans/x.nrrd", "~/x",
             "a//b", "a/./b", "a/", "sch\u00e4del/\u8133.nii.gz", "a\\b", "x" * 256]
    for i, n in enumerate(names):
        write("fuzz_volume_name", f"name_{i:02}.txt", n)
    write("fuzz_volume_name", "nul.txt", b"a\x00b")
    write("fuzz_volume_name", "cut_utf8.txt", b"a/\xc3")


def static_paths():
    # The fuzz target's web root: index.html, app/main.js, app/sub/index.html, empty/,
    # "a b%.css", escape.txt -> ../secret.txt, up -> .., inside.js -> app/main.js.
    targets = ["/", "/index.html", "/app/main.js?x=1", "/app/sub/", "/app/sub#frag", "/empty/",
               "/a%20b%25.css", "/%2e%2e/secret.txt", "/app/../../secret.txt", "/escape.txt",
               "/up/secret.txt", "/up/web/index.html", "/inside.js", "/%zz", "/a%00b", "/app\\main.js",
               "//index.html", "/./app/./main.js", "relative.html", "/%C3%A9t%C3%A9.html"]
    for i, t in enumerate(targets):
        write("fuzz_static_path", f"target_{i:02}.txt", t)


def scenes():
    for f in sorted((ROOT / "scenes").glob("*.json")):
        write("fuzz_scene", f.name, f.read_bytes())
    write("fuzz_scene", "builtin_minimal.json", '{"volume": "builtin:sphere", "transfer_function": {"preset": "ct_bone"}}')
    write("fuzz_scene", "utf8_volume.json", '{"volume": "sch\u00e4del.nrrd", "transfer_function": {"points": [[0,0,0,0,0],[1,1,1,1,1]]}}')
    write("fuzz_scene", "cut_utf8.json", b'{"volume": "\xc3')


def volume_headers():
    # The first byte picks the format (fuzz_volume_header.cpp): 0 nrrd, 1 nhdr, 2 nii,
    # 3 mhd, 4 mha. The target's folder holds data.raw (4096 bytes) and data.raw.gz.
    voxels = bytes(range(8))
    nrrd = ("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nspacings: 1 1 2.5\n"
            "encoding: raw\n\n").encode() + voxels
    write("fuzz_volume_header", "nrrd_raw.bin", b"\x00" + nrrd)
    nrrd_space = ("NRRD0005\ntype: short\ndimension: 3\nspace: left-posterior-superior\nsizes: 2 2 1\n"
                  "space directions: (1,0,0) (0,1,0) (0,0,3)\nspace origin: (10,-5,2.5)\nendian: big\n"
                  "encoding: raw\n\n").encode() + struct.pack(">4h", -3, 0, 7, 32767)
    write("fuzz_volume_header", "nrrd_space_big_endian.bin", b"\x00" + nrrd_space)
    nrrd_gz = ("NRRD0004\ntype: float\ndimension: 3\nsizes: 2 1 1\nencoding: gzip\n\n").encode() + \
        gzip.compress(struct.pack("<2f", 1.5, float("nan")), mtime=0)
    write("fuzz_volume_header", "nrrd_gzip_float_nan.bin", b"\x00" + nrrd_gz)
    nhdr = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 16 16 16\nencoding: raw\ndata file: data.raw\n"
    write("fuzz_volume_header", "nhdr_raw.bin", b"\x01" + nhdr.encode())
    nhdr_gz = "NRRD0004\ntype: uint16\ndimension: 3\nsizes: 8 16 16\nendian: little\nencoding: gzip\ndata file: data.raw.gz\n"
    write("fuzz_volume_header", "nhdr_gzip.bin", b"\x01" + nhdr_gz.encode())
    # NIfTI-1 single file: 348-byte header, 4 extension bytes, voxels at vox_offset 352.
    hdr = bytearray(348)
    struct.pack_into("<i", hdr, 0, 348)
    struct.pack_into("<8h", hdr, 40, 3, 2, 2, 2, 1, 1, 1, 1)        # dim
    struct.pack_into("<hh", hdr, 70, 2, 8)                          # datatype uint8, bitpix
    struct.pack_into("<8f", hdr, 76, 1, 1.5, 1.5, 2, 1, 1, 1, 1)    # pixdim (qfac 1)
    struct.pack_into("<f", hdr, 108, 352.0)                         # vox_offset
    struct.pack_into("<ff", hdr, 112, 1.0, 0.0)                     # scl_slope, scl_inter
    struct.pack_into("<hh", hdr, 252, 1, 0)                         # qform_code, sform_code
    hdr[344:348] = b"n+1\x00"
    write("fuzz_volume_header", "nifti_uint8.bin", b"\x02" + bytes(hdr) + b"\x00" * 4 + voxels)
    mhd = ("ObjectType = Image\nNDims = 3\nDimSize = 16 16 16\nElementSpacing = 1 1 1\n"
           "ElementType = MET_UCHAR\nElementDataFile = data.raw\n")
    write("fuzz_volume_header", "mhd_raw.bin", b"\x03" + mhd.encode())
    mha = ("ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nBinaryDataByteOrderMSB = False\n"
           "TransformMatrix = 1 0 0 0 1 0 0 0 1\nOffset = 0 0 0\nElementSpacing = 0.5 0.5 0.5\n"
           "ElementType = MET_UCHAR\nElementDataFile = LOCAL\n").encode() + voxels
    write("fuzz_volume_header", "mha_local.bin", b"\x04" + mha)


def volume_checks():
    # fuzz_volume_checks.cpp: byte 0 picks the check (0 NRRD .nhdr, 1 MetaImage .mhd,
    # 2 NIfTI .nii, 3 NIfTI .hdr with in.img, 4 DICOM slice, 5 a data file name), bytes 1-4
    # the byte count the header's sizes need (little-endian), then the file. The folder holds
    # data.raw and in.img (4096 bytes each), data.raw.gz, sub/data.raw, fifo.raw, out.raw (a
    # link out of the folder), in_link.raw (a link inside it) and dangling.raw.
    def put(name, pick, need, body):
        write("fuzz_volume_checks", name, bytes([pick]) + struct.pack("<I", need) + body)
    put("nrrd_raw_exact.bin", 0, 4096, b"NRRD0004\ntype: uint8\nsizes: 16 16 16\nencoding: raw\ndata file: data.raw\n")
    put("nrrd_gzip.bin", 0, 4096, b"NRRD0004\nencoding: gzip\ndatafile: data.raw.gz\n")
    put("nrrd_line_and_byte_skip.bin", 0, 4000, b"NRRD0004\nencoding: raw\nline skip: 1\nbyte skip: -1\ndata file: ./sub/data.raw\n")
    put("nrrd_attached.bin", 0, 8, b"NRRD0004\ntype: uint8\nencoding: raw\n\n" + bytes(range(8)))
    put("nrrd_dotdot.bin", 0, 4096, b"NRRD0004\nencoding: raw\ndata file: ../secret.raw\n")
    put("nrrd_link_out.bin", 0, 4096, b"NRRD0004\nencoding: raw\ndata file: out.raw\n")
    put("nrrd_fifo.bin", 0, 4096, b"NRRD0004\nencoding: raw\ndata file: fifo.raw\n")
    put("nrrd_list.bin", 0, 4096, b"NRRD0004\nencoding: raw\ndata file: LIST\ndata.raw\nin_link.raw\n")
    put("nrrd_pattern.bin", 0, 4096, b"NRRD0004\nencoding: raw\ndata file: dat%01d.raw 0 3 1\n")
    put("mhd_raw.bin", 1, 4096, b"ObjectType = Image\nNDims = 3\nHeaderSize = 0\nElementDataFile = data.raw\n")
    put("mhd_compressed.bin", 1, 4096, b"CompressedData = True\nElementDataFile = data.raw.gz\n")
    put("mha_local.bin", 1, 4, b"ObjectType = Image\nElementDataFile = LOCAL\n\x01\x02\x03\x04")
    put("mhd_list.bin", 1, 4096, b"ElementDataFile = LIST\ndata.raw\ndangling.raw\n")
    put("mhd_absolute.bin", 1, 4096, b"ElementDataFile = /etc/passwd\n")
    # NIfTI-1 single file and pair (the same header as fuzz_volume_header's seed).
    hdr = bytearray(348)
    struct.pack_into("<i", hdr, 0, 348)
    struct.pack_into("<8h", hdr, 40, 3, 2, 2, 2, 1, 1, 1, 1)
    struct.pack_into("<hh", hdr, 70, 2, 8)
    struct.pack_into("<8f", hdr, 76, 1, 1.5, 1.5, 2, 1, 1, 1, 1)
    struct.pack_into("<f", hdr, 108, 352.0)
    hdr[344:348] = b"n+1\x00"
    put("nifti_single.bin", 2, 0, bytes(hdr) + b"\x00" * 4 + bytes(range(8)))
    pair = bytearray(hdr)
    struct.pack_into("<8h", pair, 40, 3, 16, 16, 16, 1, 1, 1, 1)
    struct.pack_into("<f", pair, 108, 0.0)
    pair[344:348] = b"ni1\x00"
    put("nifti_pair.bin", 3, 0, bytes(pair))
    swapped = bytearray(348)
    struct.pack_into(">i", swapped, 0, 348)
    struct.pack_into(">8h", swapped, 40, 3, 2, 2, 2, 1, 1, 1, 1)
    struct.pack_into(">hh", swapped, 70, 4, 16)
    struct.pack_into(">8f", swapped, 76, 1, 1, 1, 1, 1, 1, 1, 1)
    struct.pack_into(">f", swapped, 108, 352.0)
    swapped[344:348] = b"n+1\x00"
    put("nifti_big_endian.bin", 2, 0, bytes(swapped) + b"\x00" * 4 + bytes(16))
    # NIfTI-2: 540-byte header.
    n2 = bytearray(540)
    struct.pack_into("<i", n2, 0, 540)
    n2[4:8] = b"n+2\x00"
    struct.pack_into("<hh", n2, 12, 2, 8)
    struct.pack_into("<8q", n2, 16, 3, 2, 2, 2, 1, 1, 1, 1)
    struct.pack_into("<8d", n2, 104, 1, 1, 1, 1, 1, 1, 1, 1)
    struct.pack_into("<q", n2, 168, 544)
    put("nifti2_single.bin", 2, 0, bytes(n2) + b"\x00" * 4 + bytes(8))
    # DICOM: preamble, DICM, a file meta group, rows/columns and 8 bytes of pixel data.
    def element(group, elem, vr, value):
        if vr in (b"OB", b"OW", b"UN", b"SQ", b"UT"):
            return struct.pack("<HH", group, elem) + vr + b"\x00\x00" + struct.pack("<I", len(value)) + value
        return struct.pack("<HH", group, elem) + vr + struct.pack("<H", len(value)) + value
    ts = b"1.2.840.10008.1.2.1\x00"
    meta_body = element(0x0002, 0x0010, b"UI", ts)
    meta = element(0x0002, 0x0000, b"UL", struct.pack("<I", len(meta_body))) + meta_body
    data = (element(0x0028, 0x0010, b"US", struct.pack("<H", 2)) + element(0x0028, 0x0011, b"US", struct.pack("<H", 2))
            + element(0x0028, 0x0100, b"US", struct.pack("<H", 16)) + element(0x7FE0, 0x0010, b"OW", bytes(8)))
    dicom = b"\x00" * 128 + b"DICM" + meta + data
    put("dicom_explicit.bin", 4, 8, dicom)
    put("dicom_truncated.bin", 4, 8, dicom[:-3])
    for name in ["data.raw", "../secret.raw", "out.raw", "in_link.raw", "fifo.raw", "sub", "dangling.raw",
                 "/etc/passwd", "sub/../data.raw", "sub/../../hdr/data.raw"]:
        put("name_" + re.sub(r"[^a-z]+", "_", name).strip("_") + ".bin", 5, 0, name.encode())


def http_requests():
    # The first byte is the read size minus one (fuzz_http_session.cpp); 0xff: 256-byte reads.
    def req(name, text, read=b"\xff"):
        write("fuzz_http_session", name, read + text.encode())
    host = "Host: 127.0.0.1:8080\r\n"
    req("get_index.bin", "GET / HTTP/1.1\r\n" + host + "\r\n")
    req("get_js_keepalive_then_head.bin", "GET /app/main.js?v=1 HTTP/1.1\r\n" + host + "\r\n"
        "HEAD /index.html HTTP/1.1\r\n" + host + "Connection: close\r\n\r\n")
    req("health_ready_metrics_bytewise.bin", "GET /healthz HTTP/1.1\r\n" + host + "\r\n"
        "GET /readyz HTTP/1.1\r\n" + host + "\r\nGET /metrics HTTP/1.1\r\n" + host + "\r\n", b"\x00")
    req("escape_link.bin", "GET /escape.txt HTTP/1.1\r\n" + host + "\r\n")
    req("dotdot_encoded.bin", "GET /%2e%2e/secret.txt HTTP/1.0\r\n\r\n")
    req("post_with_body.bin", "POST /ws HTTP/1.1\r\n" + host + "Content-Length: 5\r\n\r\nhello")
    req("chunked.bin", "GET / HTTP/1.1\r\n" + host + "Transfer-Encoding: chunked\r\n\r\n3\r\nabc\r\n0\r\n\r\n")
    req("upgrade_ws.bin", "GET /ws HTTP/1.1\r\n" + host + "Upgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
        "Origin: http://127.0.0.1:8080\r\n\r\n")
    req("upgrade_bad_origin.bin", "GET /ws HTTP/1.1\r\n" + host + "Upgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\nOrigin: http://evil.example\r\n\r\n")
    req("upgrade_wrong_path.bin", "GET /other HTTP/1.1\r\n" + host + "Upgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n")
    req("bad_host.bin", "GET / HTTP/1.1\r\nHost: evil.example\r\n\r\n")
    req("garbage.bin", "\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03")
    req("long_target.bin", "GET /" + "a" * 9000 + " HTTP/1.1\r\n" + host + "\r\n")


def main():
    # Seeds are rewritten in place; regression_* inputs (from findings) are left alone.
    client_messages()
    server_messages()
    frames()
    volume_names()
    static_paths()
    scenes()
    volume_headers()
    volume_checks()
    http_requests()


if __name__ == "__main__":
    main()
