"""Images: puppet warping of sprites and cut-outs (issue 48), on the planar ARAP of
:mod:`arapkit.methods.planar`. Needs the extra ``pip install 'arapkit[image]'``.

* :mod:`arapkit.image.meshing`: the shape of an image as a triangle mesh;
* :mod:`arapkit.image.raster`: arapkit's own rasteriser (bilinear sampling, anti-aliased
  outline, depth order where parts overlap);
* :mod:`arapkit.image.pins`: pins and keyframe files;
* :mod:`arapkit.image.warp`: :class:`ImageWarp` and :func:`warp_image`, what
  ``arapkit warp`` runs.
"""
