"""End to end through a client generated from openapi.yaml by openapi-python-client, used as an
integrator would, without edits: submit a vectorize and a text job, follow each job's events
(httpx-sse on the client's own httpx session, a full replay with ?from=0), read the job and
download its SVG, PNG preview, PDF and first snapshot; the text job asks for 2 variations and
the second's SVG, PNG (at a chosen size) and PDF are downloaded through their own routes.

Usage: python_e2e.py BASE_URL PNG_BASE64   (the generated package on PYTHONPATH)
Prints one line per job and exits 0, or raises.
"""

import json
import sys

from httpx_sse import connect_sse
from vectorfusion_client import Client
from vectorfusion_client.api.default import (
    get_job,
    result_pdf,
    result_png,
    result_svg,
    result_variation_pdf,
    result_variation_png,
    result_variation_svg,
    snapshot_svg,
    submit_job,
)
from vectorfusion_client.models import (
    Job,
    JobStatus,
    TextJobRequest,
    TextJobRequestKind,
    VectorizeJobRequest,
    VectorizeJobRequestKind,
)

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def submit(client, body):
    r = submit_job.sync_detailed(client=client, body=body)
    assert r.status_code == 202, (r.status_code, r.content)
    assert isinstance(r.parsed, Job), r.parsed
    return r.parsed


def follow(client, job_id):
    """The event names of the job's stream, from a full replay to the terminal event."""
    names = []
    with connect_sse(
        client.get_httpx_client(), "GET", f"/jobs/{job_id}/events", params={"from": 0}
    ) as source:
        for ev in source.iter_sse():
            json.loads(ev.data)  # every event's data is one JSON object
            assert ev.id.isdigit(), ev.id  # and every event is a resumption point
            names.append(ev.event)
            if ev.event in ("done", "failed", "cancelled"):
                break
    return names


def check(client, job):
    names = follow(client, job.id)
    assert names[0] == "state" and names[-1] == "done", names
    assert "snapshot" in names, names
    view = get_job.sync(id=job.id, client=client)
    assert isinstance(view, Job) and view.status == JobStatus.SUCCEEDED, view
    svg = result_svg.sync(id=job.id, client=client)
    assert isinstance(svg, bytes) and svg.startswith(b"<svg"), svg[:40]
    png = result_png.sync(id=job.id, client=client)
    assert isinstance(png, bytes) and png.startswith(PNG_MAGIC), png[:8]
    pdf = result_pdf.sync(id=job.id, client=client)
    assert isinstance(pdf, bytes) and pdf.startswith(b"%PDF-"), pdf[:8]
    snap = snapshot_svg.sync(id=job.id, n=1, client=client)
    assert isinstance(snap, bytes) and snap.startswith(b"<svg"), snap[:40]
    big = result_png.sync(id=job.id, client=client, size=200)
    assert png_side(big) == 200, png_side(big)
    print(f"{view.kind.value} {job.id}: {len(names)} events, svg {len(svg)} B, png {len(png)} B")
    return svg


def png_side(png):
    """The longer side of a PNG, from its IHDR."""
    assert isinstance(png, bytes) and png.startswith(PNG_MAGIC), png[:8]
    return max(int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big"))


def check_variation(client, job_id, first_svg):
    """Variation 2 of a text job: its own SVG, its PNG at 64 px, its PDF."""
    svg = result_variation_svg.sync(id=job_id, i=2, client=client)
    assert isinstance(svg, bytes) and svg.startswith(b"<svg") and svg != first_svg, svg[:40]
    png = result_variation_png.sync(id=job_id, i=2, client=client, size=64)
    assert png_side(png) == 64, png_side(png)
    pdf = result_variation_pdf.sync(id=job_id, i=2, client=client)
    assert isinstance(pdf, bytes) and pdf.startswith(b"%PDF-"), pdf[:8]
    print(f"variation 2 of {job_id}: svg {len(svg)} B, png {len(png)} B, pdf {len(pdf)} B")


def main():
    base, png_b64 = sys.argv[1], sys.argv[2]
    with Client(base_url=base, raise_on_unexpected_status=True, timeout=60.0) as client:
        jobs = [
            submit(
                client,
                VectorizeJobRequest(
                    kind=VectorizeJobRequestKind.VECTORIZE, image=png_b64, paths=4, steps=6, seed=7
                ),
            ),
            submit(
                client,
                TextJobRequest(
                    kind=TextJobRequestKind.TEXT,
                    caption="a red apple",
                    paths=4,
                    steps=6,
                    seed=9,
                    variations=2,
                ),
            ),
        ]
        svgs = [check(client, job) for job in jobs]
        check_variation(client, jobs[1].id, svgs[1])


if __name__ == "__main__":
    main()
