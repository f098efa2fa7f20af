"""A dataset on S3 (moto's server on loopback) reads the same arrays as on disk."""

import os
import shutil
import socket
import subprocess
import time

import numpy as np
import pytest

import nrw


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def moto():
    if shutil.which("moto_server") is None:
        if os.environ.get("NRW_REQUIRE_S3") == "1":
            pytest.fail("moto_server is required (NRW_REQUIRE_S3=1): pip install 'moto[server]'")
        pytest.skip("moto_server not found (pip install 'moto[server]')")
    port = free_port()
    server = subprocess.Popen(["moto_server", "-H", "127.0.0.1", "-p", str(port)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 60
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            break
        except OSError:
            assert time.time() < deadline, "moto_server did not start"
            time.sleep(0.1)
    yield f"http://127.0.0.1:{port}"
    server.terminate()
    server.wait()


def test_a_dataset_on_s3_reads_the_same_arrays(demo, moto):
    import boto3

    s3 = boto3.client("s3", endpoint_url=moto, region_name="us-east-1",
                      aws_access_key_id="nrwtest", aws_secret_access_key="nrwtest")
    s3.create_bucket(Bucket="nrw")
    for folder, _, files in os.walk(demo):
        for f in files:
            path = os.path.join(folder, f)
            s3.upload_file(path, "nrw", "demo/" + os.path.relpath(path, demo))
    options = {"aws_endpoint_url": moto, "aws_allow_http": "true", "aws_region": "us-east-1",
               "aws_access_key_id": "nrwtest", "aws_secret_access_key": "nrwtest"}
    remote, local = nrw.Dataset("s3://nrw/demo", options), nrw.Dataset(demo)
    assert len(remote) == len(local) and remote.splits() == local.splits()
    pairs = list(zip(remote.views(), local.views()))
    assert len(pairs) == len(local)
    for r, l in pairs:
        assert r.keys() == l.keys()
        for key, value in l.items():
            if isinstance(value, np.ndarray):
                np.testing.assert_array_equal(r[key], value, err_msg=key)
            else:
                assert r[key] == value, key
    assert remote.triplets().equals(local.triplets())
    assert remote.descriptors().equals(local.descriptors())
    with pytest.raises(nrw.DatasetError, match="s3://nrw/nothing"):
        nrw.Dataset("s3://nrw/nothing", options)
