#!/usr/bin/env python3
"""Open a volume, orbit the camera once around it, wait for the final frame and save it.

    /usr/bin/python3 client/python/examples/orbit.py --volume bonsai -o out/orbit.png
    /usr/bin/python3 client/python/examples/orbit.py --file head.nii.gz -o out/orbit.png

Needs a running volcast server and websockets (Debian: python3-websockets, so run it with
/usr/bin/python3). Uses the volcast package beside this folder, or the installed one
(pip install ./client/python). Prints one line per frame: sequence number, level, codec,
size, render and encode times and the error estimate, so the ladder from interactive to final
frames can be watched; with numpy and Pillow, also the final frame's mean colour.
"""

import argparse
import asyncio
import os
import sys

# The source tree's package when run from it; otherwise the installed one.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
import volcast as vc  # noqa: E402


def describe(frame: vc.Frame) -> str:
    error = frame.error
    estimate = f"{error['value']:.2e} ({error['method']})" if error else "-"
    return (f"seq {frame.seq:5d}  level {frame.level}  {frame.codec:4s} {frame.width}x{frame.height}  "
            f"render {frame.render_ms:7.1f} ms  encode {frame.encode_ms:6.1f} ms  "
            f"error {estimate}{'  final' if frame.final else ''}")


async def orbit(args) -> int:
    async with await vc.Client.connect(args.url, token=args.token, client_name="orbit.py") as client:
        server = client.server_hello
        print(f"server {server['server']} on {server['device']['name']} ({server['device']['type']})")

        def progress(p):
            # A DICOMweb series reports instances and bytes while retrieving, not a fraction.
            done = [f"{100 * p['fraction']:.0f}%"] if "fraction" in p else []
            if "instances" in p:
                done.append(f"{p['instances'][0]}/{p['instances'][1]} instances")
            if "bytes" in p:
                done.append(f"{p['bytes'] / 2**20:.1f} MiB")
            print(f"  {p['stage']} {p.get('task', '')} {', '.join(done)}", flush=True)

        name = args.volume
        if args.file:
            name = await client.upload(args.file)
            print(f"uploaded {args.file} as {name}")
        state = await client.open_volume(name, on_progress=progress)
        info = state["volume"]
        print(f"opened {info['name']}: dims {info.get('dims')}, spacing {info.get('spacing')}")
        width, height = (int(v) for v in args.size.split("x"))
        await client.send(vc.viewport(width, height))
        await client.send(vc.quality_automatic(target_frame_ms=args.target_ms))

        # The server chose a camera on open; turn its eye about the target along "up".
        base = state["scene"]["camera"]
        await client.send(vc.interaction_start())
        last = None
        for step in range(args.steps + 1):
            last = await client.send(vc.camera(vc.orbit_camera(base, 360.0 * step / args.steps)))
            # Show the frames that arrive while pacing the orbit at the frame-time target.
            deadline = asyncio.get_running_loop().time() + args.target_ms / 1000
            while (left := deadline - asyncio.get_running_loop().time()) > 0:
                item = await client.receive(timeout=left)
                if isinstance(item, vc.Frame):
                    print(describe(item))
                elif item is not None and item.get("type") == "error":
                    raise vc.ServerError(item)
        await client.send(vc.interaction_end())

        final = await client.wait_for_final_frame(request=last, timeout=args.timeout,
                                                  on_frame=lambda f: print(describe(f)))
        print(describe(final))
        os.makedirs(os.path.dirname(os.path.abspath(args.output)), exist_ok=True)
        with open(args.output, "wb") as out:
            out.write(final.image)
        print(f"wrote {args.output} ({final.codec}, {len(final.image)} bytes)")
        try:
            pixels = final.to_numpy()  # height x width x RGBA, uint8
            print(f"mean RGBA {pixels.reshape(-1, 4).mean(axis=0).round(1).tolist()}")
        except vc.MissingDependencyError as e:
            print(f"(no pixel statistics: {e})")
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default="ws://127.0.0.1:8080/ws", help="the server's WebSocket URL")
    parser.add_argument("--token", help="access token, if the server asks for one")
    which = parser.add_mutually_exclusive_group(required=True)
    which.add_argument("--volume", help='a name from list_volumes ("bonsai"), a find_studies series\' '
                                        '"dicomweb:SOURCE/STUDY/SERIES", or an upload\'s "upload:<id>"')
    which.add_argument("--file", help="a volume file of this machine to upload first (.nrrd, .nii, "
                                      ".nii.gz, .mha, or a .zip of a DICOM series)")
    parser.add_argument("--steps", type=int, default=36, help="camera positions in one turn")
    parser.add_argument("--size", default="512x512", help="viewport WIDTHxHEIGHT in pixels")
    parser.add_argument("--target-ms", type=float, default=40, help="frame-time target while orbiting, ms")
    parser.add_argument("--timeout", type=float, default=300, help="seconds to wait for the final frame")
    parser.add_argument("-o", "--output", default="orbit.png", help="where the final frame goes")
    args = parser.parse_args()
    try:
        return asyncio.run(orbit(args))
    except vc.ServerError as e:
        print(f"orbit.py: server refused: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
