"""The file plumbing starts without torch: every module of
``wgse_mmseg.fileio`` imports without torch, OpenCV or OpenMMLab, so the
tools' readers, writers and argument parsers load at once."""
import glob
import os.path as osp
import subprocess
import sys

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))


def test_the_file_plumbing_imports_no_torch():
    names = sorted(osp.basename(path)[:-3] for path in glob.glob(
        osp.join(ROOT, 'wgse_mmseg', 'fileio', '*.py')))
    script = ('import sys\n' + ''.join(
        f'import wgse_mmseg.fileio.{name}\n' for name in names
        if name != '__init__') + 'print(sorted(m for m in sys.modules if '
        'm.split(".")[0] in ("torch", "cv2", "mmengine", "mmseg")))')
    proc = subprocess.run([sys.executable, '-c', script], cwd=ROOT,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.split() == ['[]']
    assert len(names) > 10  # the glob found the package
