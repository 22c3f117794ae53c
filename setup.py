"""Install wgse_mmseg.

Like MMSegmentation, the package carries its ``configs/`` and ``tools/`` inside
``wgse_mmseg/.mim/`` so that ``mim train wgse_mmseg configs/<config>.py``
finds both from a regular install. A regular build copies them there. The
editable installs of the two stacks' mims differ (docs/install.md):
OpenMMLab's mim 0.3.8 looks in ``wgse_mmseg/.mim`` of an egg-link install
(``setup.py develop``), so that links them and edits take effect at once;
onedl-mim takes a PEP 660 install (``editable_wheel``) to be this checkout,
whose root holds ``configs/`` and ``tools/`` and where it searches a config
by its name, so there ``.mim`` is left out (a second copy would make every
name ambiguous).
"""
import os
import os.path as osp
import shutil
import sys

from setuptools import Extension, find_packages, setup

ROOT = osp.dirname(osp.abspath(__file__))
MIM_DIRS = ('configs', 'tools')


def version():
    namespace = {}
    with open(osp.join(ROOT, 'wgse_mmseg', 'version.py')) as f:
        exec(f.read(), namespace)
    return namespace['__version__']


def add_mim_extension():
    """Place configs/ and tools/ under wgse_mmseg/.mim: copies for a regular
    build, links for an egg-link install, nothing for a PEP 660 one."""
    mim_root = osp.join(ROOT, 'wgse_mmseg', '.mim')
    if 'editable_wheel' in sys.argv:
        if osp.islink(mim_root) or osp.isfile(mim_root):
            os.remove(mim_root)
        elif osp.isdir(mim_root):
            shutil.rmtree(mim_root)
        return
    os.makedirs(mim_root, exist_ok=True)
    for name in MIM_DIRS:
        src, dst = osp.join(ROOT, name), osp.join(mim_root, name)
        if osp.islink(dst) or osp.isfile(dst):
            os.remove(dst)
        elif osp.isdir(dst):
            shutil.rmtree(dst)
        if 'develop' in sys.argv:
            os.symlink(osp.relpath(src, mim_root), dst)
        else:
            shutil.copytree(src, dst, ignore=shutil.ignore_patterns(
                '__pycache__', '*.pyc'))


if __name__ == '__main__':
    add_mim_extension()
    setup(
        name='wgse_mmseg',
        version=version(),
        description='Wavelet-guided spike enhancing (WGSE) and spike-camera '
        'data for MMSegmentation',
        long_description=open(osp.join(ROOT, 'README.md'),
                              encoding='utf-8').read(),
        long_description_content_type='text/markdown',
        license='Apache-2.0',
        python_requires='>=3.9',
        # the library, and beside it the measurement wing (benchmarks,
        # experiment grids), which the library never imports
        packages=find_packages(include=['wgse_mmseg', 'wgse_mmseg.*',
                                        'wgse_bench', 'wgse_bench.*']),
        include_package_data=True,
        package_data={'wgse_mmseg': ['.mim/**/*', '.mim/**/**/*',
                                     '.mim/**/**/**/*', 'weights/*.pth',
                                     'evaluation/quality/data/*']},
        # The OpenMMLab stack is an extra, one per stack: both publish the
        # import packages mmseg, mmengine, mmcv and mim, so naming one here
        # would install it over the other (docs/install.md;
        # tools/setup_env.sh pins either). The MMSeg layer says at import
        # which is missing (wgse_mmseg.openmmlab_stack.require_openmmlab).
        install_requires=[
            'torch>=2.0',
            'numpy',
            'PyWavelets>=1.4',
            'opencv-python>=4.8,<5',  # 5 rejects arrays of > 128 channels
            'Pillow>=9.1',  # image headers, read before decoding (fileio)
            'PyYAML>=6',  # scene files (fileio.scene_files)
            'tqdm',
        ],
        extras_require={
            'tests': ['pytest>=7', 'hypothesis>=6.80'],
            # mmcv-lite or mmcv 2.1: tools/setup_env.sh picks (MMCV=lite|full)
            'openmmlab': ['mmengine>=0.10,<0.11', 'mmsegmentation>=1.2,<1.3',
                          'openmim==0.3.8'],
            'onedl': ['onedl-mmengine>=0.10.12,<0.11',
                      'onedl-mmsegmentation>=1.4.2,<1.5',
                      'onedl-mmcv>=2.3.6,<2.4', 'onedl-mim>=0.5.1,<0.6'],
        },
        # Two small CPU kernels: the simulator's one-pass integrate-and-fire
        # and WGSE's band networks. Optional: without a C compiler the
        # install goes on and each falls back to its torch path (the same
        # results, slower): see
        # core.simulation.fixed_point.compiled_unavailable and
        # core.wgse.compiled_band_networks.unavailable.
        ext_modules=[
            Extension(f'wgse_mmseg.{name}',
                      [f'wgse_mmseg/{name.replace(".", "/")}.c'],
                      extra_compile_args=['-O3'], optional=True)
            for name in ('core.simulation._integrate_and_fire',
                         'core.wgse._band_networks')
        ],
        zip_safe=False,
    )
