"""Make the NIQE and BRISQUE model files that the package ships.

    python dev/extract_quality_models.py [--out DIR]

The no-reference measures (:mod:`wgse_mmseg.evaluation.quality`) need published
model data, which the package ships in ``wgse_mmseg/evaluation/quality/data``
so that nothing is downloaded at run time. This script makes those files from
pinned registry packages (it needs the registry; CI does not run it):

* ``niqe_pristine_model.npz``: ``basicsr/metrics/niqe_pris_params.npz`` of
  basicsr 1.4.2's sdist, copied byte for byte (the pristine model of the
  NIQE MATLAB release: ``mu_pris_param`` (1, 36), ``cov_pris_param``
  (36, 36), ``gaussian_window`` (7, 7); read here without pickles);
* ``brisque_svr_model.npz``: ``brisque/models/svm.txt`` of brisque 0.2.0's
  wheel (libsvm text, an epsilon-SVR with RBF kernel) as arrays
  ``support_vectors`` (770, 36), ``dual_coef`` (770,), ``rho``, ``gamma``
  (the decimal numbers parsed to float64 as libsvm parses them);
* ``brisque_feature_range.json``: ``brisque/models/normalize.pickle`` of the
  same wheel (``min_``/``max_`` of the 36 features) as JSON, read by an
  unpickler that refuses every import, so no code in it can run;
* ``LICENSE.basicsr.txt``, ``LICENSE.brisque.txt``: both Apache-2.0;
* ``SOURCES.json``: the record: each file's SHA-256, package, archive
  SHA-256 and member. ``tests/evaluation/test_quality.py`` checks the shipped
  files against it.

The archives are fetched with ``pip download`` (pinned version, no
dependencies) and checked against their SHA-256 before anything is read;
the ``.npz`` files are written with fixed timestamps, so a run reproduces
the shipped files byte for byte.
"""
import argparse
import hashlib
import io
import json
import os.path as osp
import pickle
import subprocess
import sys
import tarfile
import tempfile
import zipfile

import numpy as np

from wgse_mmseg.command_line import Path
from wgse_mmseg.fileio.atomic import write_bytes
from wgse_mmseg.fileio.output_folder import check_tool_outputs
from wgse_mmseg.fileio.input_guard import keeps_inputs

DEFAULT_OUT = osp.join(osp.dirname(osp.dirname(osp.abspath(__file__))),
                       'wgse_mmseg', 'core', 'quality', 'data')

#: the pinned archives: pip requirement, pip options, file name, SHA-256
BASICSR = ('basicsr==1.4.2', ['--no-binary', ':all:'],
           'basicsr-1.4.2.tar.gz',
           'b89b595a87ef964cda9913b4d99380ddb6554c965577c0c10cb7b78e31301e87')
BRISQUE = ('brisque==0.2.0', ['--only-binary', ':all:'],
           'brisque-0.2.0-py3-none-any.whl',
           '56f1839e5179a294d0598d63b2ee488fcbedeac7cee3e32c7c8d06c30a6269e1')
NIQE_MEMBER = 'basicsr-1.4.2/basicsr/metrics/niqe_pris_params.npz'
BASICSR_LICENSE = 'basicsr-1.4.2/LICENSE.txt'
SVM_MEMBER = 'brisque/models/svm.txt'
RANGE_MEMBER = 'brisque/models/normalize.pickle'
BRISQUE_LICENSE = 'brisque-0.2.0.dist-info/licenses/LICENSE'
NUM_FEATURES = 36


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description='Make the NIQE/BRISQUE model files from pinned packages')
    parser.add_argument('--out', type=Path(), default=DEFAULT_OUT,
                        help='output folder (default: the package\'s '
                        'wgse_mmseg/evaluation/quality/data)')
    return parser


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def download(pin, folder: str) -> bytes:
    """The pinned archive's bytes, its SHA-256 checked."""
    requirement, options, name, digest = pin
    subprocess.run([sys.executable, '-m', 'pip', 'download', '--no-deps',
                    *options, requirement, '-d', folder], check=True)
    with open(osp.join(folder, name), 'rb') as f:
        data = f.read()
    if sha256(data) != digest:
        raise ValueError(f'{name}: SHA-256 {sha256(data)}, expected {digest}')
    return data


class _NoImports(pickle.Unpickler):
    """Builds only pickle's own types (dict, list, str, float, ...)."""

    def find_class(self, module, name):
        raise pickle.UnpicklingError(
            f'refused: the pickle imports {module}.{name}')


def feature_range(pickled: bytes) -> dict:
    """``{'min': [...], 'max': [...]}`` of brisque's ``normalize.pickle``
    (a dict of two lists of 36 floats); refuses any pickle that imports."""
    data = _NoImports(io.BytesIO(pickled)).load()
    if not (isinstance(data, dict) and set(data) == {'min_', 'max_'} and all(
            isinstance(v, list) and len(v) == NUM_FEATURES
            and all(type(x) is float for x in v) for v in data.values())):
        raise ValueError(f'{RANGE_MEMBER}: expected min_ and max_, '
                         f'{NUM_FEATURES} floats each')
    return {'min': data['min_'], 'max': data['max_']}


def svr_model(text: str) -> dict:
    """The arrays of a libsvm text model of an RBF epsilon-SVR."""
    header, _, body = text.partition('\nSV\n')
    fields = dict(line.split(' ', 1) for line in header.splitlines())
    if (fields.get('svm_type'), fields.get('kernel_type')) != (
            'epsilon_svr', 'rbf'):
        raise ValueError(f'{SVM_MEMBER}: expected an RBF epsilon-SVR')
    rows = [line.split() for line in body.splitlines() if line.strip()]
    if len(rows) != int(fields['total_sv']):
        raise ValueError(f'{SVM_MEMBER}: {len(rows)} support vectors, '
                         f'header says {fields["total_sv"]}')
    vectors = np.zeros((len(rows), NUM_FEATURES), np.float64)
    for row, items in enumerate(rows):
        for item in items[1:]:  # index:value, 1-based, zeros left out
            index, value = item.split(':')
            vectors[row, int(index) - 1] = float(value)
    return dict(support_vectors=vectors,
                dual_coef=np.array([float(r[0]) for r in rows]),
                rho=np.array(float(fields['rho'])),
                gamma=np.array(float(fields['gamma'])))


def npz_bytes(arrays: dict) -> bytes:
    """An uncompressed ``.npz`` of ``arrays`` with fixed timestamps (the
    same bytes on every run)."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, 'w', zipfile.ZIP_STORED) as archive:
        for key, value in arrays.items():
            member = io.BytesIO()
            np.lib.format.write_array(member, np.asarray(value),
                                      allow_pickle=False)
            info = zipfile.ZipInfo(f'{key}.npy', date_time=(1980, 1, 1, 0, 0,
                                                            0))
            archive.writestr(info, member.getvalue())
    return buffer.getvalue()


def check_niqe_model(data: bytes) -> None:
    with np.load(io.BytesIO(data), allow_pickle=False) as arrays:
        shapes = {k: arrays[k].shape for k in arrays.files}
    if shapes != {'mu_pris_param': (1, NUM_FEATURES),
                  'cov_pris_param': (NUM_FEATURES, NUM_FEATURES),
                  'gaussian_window': (7, 7)}:
        raise ValueError(f'{NIQE_MEMBER}: unexpected arrays {shapes}')


def make_files(basicsr_sdist: bytes, brisque_wheel: bytes) -> dict:
    """``{file name: (bytes, record)}`` of every shipped file."""
    files = {}
    with tarfile.open(fileobj=io.BytesIO(basicsr_sdist)) as sdist:
        niqe = sdist.extractfile(NIQE_MEMBER).read()
        licence = sdist.extractfile(BASICSR_LICENSE).read()
    check_niqe_model(niqe)
    source = dict(package=BASICSR[0], archive=BASICSR[2],
                  archive_sha256=BASICSR[3])
    files['niqe_pristine_model.npz'] = (niqe, dict(
        source, member=NIQE_MEMBER, member_sha256=sha256(niqe),
        conversion='none (copied byte for byte)'))
    files['LICENSE.basicsr.txt'] = (licence, dict(
        source, member=BASICSR_LICENSE, member_sha256=sha256(licence),
        conversion='none'))
    with zipfile.ZipFile(io.BytesIO(brisque_wheel)) as wheel:
        svm = wheel.read(SVM_MEMBER)
        pickled = wheel.read(RANGE_MEMBER)
        licence = wheel.read(BRISQUE_LICENSE)
    source = dict(package=BRISQUE[0], archive=BRISQUE[2],
                  archive_sha256=BRISQUE[3])
    files['brisque_svr_model.npz'] = (npz_bytes(svr_model(svm.decode())),
                                      dict(source, member=SVM_MEMBER,
                                           member_sha256=sha256(svm),
                                           conversion='libsvm text to '
                                           'float64 arrays'))
    files['brisque_feature_range.json'] = (
        (json.dumps(feature_range(pickled), indent=1) + '\n').encode(),
        dict(source, member=RANGE_MEMBER, member_sha256=sha256(pickled),
             conversion='pickle read without imports, to JSON'))
    files['LICENSE.brisque.txt'] = (licence, dict(
        source, member=BRISQUE_LICENSE, member_sha256=sha256(licence),
        conversion='none'))
    return files


@keeps_inputs
def main(argv=None):
    args = build_parser().parse_args(argv)
    check_tool_outputs(args, 'out')
    with tempfile.TemporaryDirectory() as folder:
        files = make_files(download(BASICSR, folder),
                           download(BRISQUE, folder))
    record = {}
    for name, (data, source) in files.items():
        write_bytes(osp.join(args.out, name), data)
        record[name] = dict(sha256=sha256(data), size=len(data), **source)
        print(f'{name}\t{len(data)} bytes\tsha256={sha256(data)}')
    write_bytes(osp.join(args.out, 'SOURCES.json'),
                (json.dumps(record, indent=1) + '\n').encode())


if __name__ == '__main__':
    main()
