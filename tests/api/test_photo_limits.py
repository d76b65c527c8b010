"""A finding's photo may declare at most 40 MP: a small file declaring a huge
picture is refused at upload, one stored before the limit is not decoded by a
report (a viewer's request), and ordinary photos still get their thumbnails.

Nothing large is allocated here: the huge picture is a real 1 × 1 PNG whose
header says 13000 × 13000, which is all a reader sees before it decodes."""

from __future__ import annotations

import io
import struct
import zlib
from typing import Any

import pytest
from PIL import Image, ImageFile

from server.reports import data as report_data
from server.reports.data import PhotoTooLarge, gather, thumbnail
from server.store.findings import PHOTO_MAX_PIXELS, FindingStore

SIDE = 13_000  # 169 MP: 1.3 GB once decoded


def png_declaring(width: int, height: int) -> bytes:
    """A 1 × 1 PNG with its IHDR rewritten to ``width`` × ``height`` (and its CRC fixed)."""
    buf = io.BytesIO()
    Image.new("RGB", (1, 1), (90, 90, 90)).save(buf, format="PNG")
    raw = bytearray(buf.getvalue())
    # signature (8), chunk length (4), b"IHDR" (4), width and height (4 + 4),
    # five one-byte fields, then the CRC of the type and the 13 data bytes.
    assert raw[12:16] == b"IHDR"
    raw[16:24] = struct.pack(">II", width, height)
    raw[29:33] = struct.pack(">I", zlib.crc32(bytes(raw[12:29])))
    return bytes(raw)


def jpeg(width: int, height: int) -> bytes:
    buf = io.BytesIO()
    Image.new("RGB", (width, height), (180, 90, 40)).save(buf, format="JPEG", quality=80)
    return buf.getvalue()


@pytest.fixture
def finding(api: Any) -> tuple[str, str]:
    """A plan and a finding on it, straight in the store (the REST route needs a
    planned inspection; the photo routes only need the finding)."""
    store = api.services.store
    plan = store.create_plan("demo.route", {}, "planner (tk_p)")
    fs = FindingStore(store.db, store.data_dir / "photos")
    f = fs.add(
        {"plan_id": plan.id, "member_id": 1, "point_m": [1.0, 2.0, 3.0], "type": "corrosion",
         "condition_state": 3},
        "inspector (tk_x)",
    )  # fmt: skip
    return plan.id, f.id


@pytest.fixture
def loads(monkeypatch: pytest.MonkeyPatch) -> list[tuple[int, int]]:
    """The size of every image Pillow decodes from now on; one over the limit
    raises instead (the test process must not allocate it either)."""
    seen: list[tuple[int, int]] = []
    original = ImageFile.ImageFile.load

    def spy(self: ImageFile.ImageFile) -> Any:
        seen.append(self.size)
        if self.size[0] * self.size[1] > PHOTO_MAX_PIXELS:
            raise MemoryError(f"decoding {self.size}")
        return original(self)

    monkeypatch.setattr(ImageFile.ImageFile, "load", spy)
    return seen


def test_the_test_image_declares_13000_square_and_is_tiny() -> None:
    raw = png_declaring(SIDE, SIDE)
    assert len(raw) < 200
    # Pillow's own process-wide limit only warns at this size (it raises from
    # 179 MP): why the server checks the declared size itself.
    with pytest.warns(Image.DecompressionBombWarning), Image.open(io.BytesIO(raw)) as im:
        assert im.size == (SIDE, SIDE)


def test_upload_of_a_photo_declaring_169_mp_is_refused(api: Any, finding: tuple[str, str]) -> None:
    _, fid = finding
    url = f"/api/v1/findings/{fid}/photos"
    r = api.post(url, files={"file": ("huge.png", png_declaring(SIDE, SIDE), "image/png")})
    assert r.status_code == 422, r.text
    msg = r.json()["detail"][0]["msg"]
    assert str(SIDE * SIDE) in msg and str(PHOTO_MAX_PIXELS) in msg, msg
    assert api.get(f"/api/v1/findings/{fid}", "viewer").json()["photos"] == []
    # Just over the limit is refused too; a header Pillow cannot parse as well.
    over = png_declaring(PHOTO_MAX_PIXELS // 4000 + 1, 4000)
    assert api.post(url, files={"file": ("o.png", over, "image/png")}).status_code == 422
    broken = b"\x89PNG\r\n\x1a\n" + b"\x00" * 64
    r = api.post(url, files={"file": ("b.png", broken, "image/png")})
    assert r.status_code == 422 and "header" in r.text, r.text
    # At the limit (40 MP declared) and an ordinary photo: accepted.
    at = png_declaring(PHOTO_MAX_PIXELS // 4000, 4000)
    assert api.post(url, files={"file": ("a.png", at, "image/png")}).status_code == 201
    r = api.post(url, files={"file": ("rust.jpg", jpeg(64, 48), "image/jpeg")})
    assert r.status_code == 201, r.text


def test_upload_reads_only_the_header(
    api: Any, finding: tuple[str, str], loads: list[tuple[int, int]]
) -> None:
    _, fid = finding
    url = f"/api/v1/findings/{fid}/photos"
    r = api.post(url, files={"file": ("huge.png", png_declaring(SIDE, SIDE), "image/png")})
    assert r.status_code == 422
    assert api.post(url, files={"file": ("ok.jpg", jpeg(64, 48), "image/jpeg")}).status_code == 201
    assert loads == []


def test_a_stored_huge_photo_is_not_decoded_by_the_report(
    api: Any, finding: tuple[str, str], loads: list[tuple[int, int]]
) -> None:
    """One stored before the limit (or imported) bypasses the upload check: the
    report notes it instead of decoding it or embedding its bytes."""
    pid, fid = finding
    store = api.services.store
    fs = FindingStore(store.db, store.data_dir / "photos")
    huge = fs.add_photo(fid, png_declaring(SIDE, SIDE), "huge.png", "image/png", "old (tk_o)")
    fine = fs.add_photo(fid, jpeg(1600, 1200), "rust.jpg", "image/jpeg", "old (tk_o)")

    photos = {p.id: p for p in gather(api.services, pid).findings[0].photos}
    assert all(w * h <= PHOTO_MAX_PIXELS for w, h in loads), loads
    assert photos[huge.id].data_uri is None
    assert str(SIDE * SIDE) in photos[huge.id].note and "not shown" in photos[huge.id].note
    # The other photo of the same finding still gets its thumbnail.
    uri = photos[fine.id].data_uri
    assert uri is not None and uri.startswith("data:image/png;base64,")
    assert photos[fine.id].note == ""

    # The viewer's request: the page answers, with the note.
    r = api.get(f"/api/v1/reports/{pid}", "viewer")
    assert r.status_code == 200, r.text
    assert f"{SIDE} × {SIDE} px" in r.text
    assert all(w * h <= PHOTO_MAX_PIXELS for w, h in loads), loads


def test_thumbnail_refuses_before_decoding(loads: list[tuple[int, int]]) -> None:
    with pytest.raises(PhotoTooLarge) as exc:
        thumbnail(png_declaring(SIDE, SIDE))
    assert (exc.value.width, exc.value.height) == (SIDE, SIDE)
    assert loads == []


def test_thumbnails_of_ordinary_photos(loads: list[tuple[int, int]]) -> None:
    """A JPEG is decoded at a reduced scale (draft), a PNG once, both at most THUMB_PX."""
    big = jpeg(4000, 3000)
    out = thumbnail(big)
    assert out is not None
    with Image.open(io.BytesIO(out)) as im:
        assert im.format == "PNG" and max(im.size) == report_data.THUMB_PX
    assert loads and max(w * h for w, h in loads) <= 4000 * 3000 // 4  # 1/2 scale or less

    buf = io.BytesIO()
    Image.new("RGBA", (900, 300), (10, 200, 30, 128)).save(buf, format="PNG")
    out = thumbnail(buf.getvalue())
    assert out is not None
    with Image.open(io.BytesIO(out)) as im:
        assert im.size == (480, 160) and im.mode == "RGBA"
    # Not an image at all: None (the report embeds small bytes as they are).
    assert thumbnail(b"\x89PNG\r\n\x1a\n" + b"\x00" * 64) is None
