"""Names of node types, edge types and attributes of a pair graph, defined once.

Import these constants; never retype the strings.

Layout of a pair graph (:func:`strl_pyg.data.build_pair_graph`)::

    data[POINT]      kpts0, kpts1 [Np, 2]  pixel coordinates in image 0 / image 1
                     pos0, pos1   [Np, 2]  normalised coordinates (see ``NORM_*``)
                     patch0, patch1 [Np, C*p*p]  pixels sampled around kpts (optional)
                     score        [Np]     match confidence (optional)
    data[ENDPOINT]   the same keys for the 2*Nl line endpoints, ordered so that
                     nodes 2i and 2i+1 are the two endpoints of line i, plus
                     line_feat    [2*Nl, 8] (x0, y0, dx0, dy0, x1, y1, dx1, dy1), normalised,
                                  delta = other endpoint - this endpoint
    data[LINE_EDGE]  edge_index [2, 2*Nl]  endpoint 2i <-> 2i+1, both directions
    data[et] for et in SELF_EDGE_TYPES (4 types: point/endpoint to point/endpoint):
                     either ``dense`` [1] (bool, implicit complete bipartite edges between the
                     two node types of the same pair; the default) or ``edge_index`` (explicit).
    graph level      image_size0, image_size1 [1, 2] (H, W); K0, K1 [1, 3, 3] when known;
                     T_0to1 [1, 4, 4] when a ground-truth pose is given;
                     image0, image1 [1, C, H, W] float in [0, 1] with keep_images=True.

One set of complete edges serves every attention of the dual graph: the GCG and the GGVG share
their node set (node ``i`` of both streams is the same match), so the GCG self-attention, the
GGVG self-attention and the Geometry-Guided cross-attention all run over the ``self`` edges of a
pair. For the cross-attention, the edge ``j -> i`` reads keys and values from the GGVG (visual)
feature of source ``j`` and the query from the GCG (geometric) feature of target ``i``, and it
updates the visual feature of ``i`` (:class:`strl_pyg.nn.DualGraphLayer`, step 4).

Optional: explicit ``edge_index`` tensors on the CROSS_EDGE_TYPES give the cross-attention an
edge set of its own (for example k-nearest neighbours); graphs built by this package carry none.
Graphs saved by strl-pyg 0.1.x carry implicit ``cross`` markers as well. Beside implicit
``self`` edges they mean the same complete edges, so the model ignores them and
:func:`strl_pyg.data.load_graph` drops them; beside explicit ``self`` edges they keep their
0.1.x meaning (complete cross-attention) and are kept.
"""

from __future__ import annotations

# Node types.
POINT = "point"
ENDPOINT = "endpoint"
NODE_TYPES = (POINT, ENDPOINT)

# Edge relations.
SELF_REL = "self"  # intra-graph self-attention: every node of a pair to every node of it
LINE_REL = "line"  # the two endpoints of one matched line segment
# Optional explicit edges of the Geometry-Guided cross-attention (see the module docstring);
# absent from built graphs, where the cross-attention runs over the SELF_EDGE_TYPES.
CROSS_REL = "cross"

LINE_EDGE = (ENDPOINT, LINE_REL, ENDPOINT)
SELF_EDGE_TYPES = tuple((s, SELF_REL, d) for s in NODE_TYPES for d in NODE_TYPES)
CROSS_EDGE_TYPES = tuple((s, CROSS_REL, d) for s in NODE_TYPES for d in NODE_TYPES)
COMPLETE_EDGE_TYPES = SELF_EDGE_TYPES  # the edge types that are complete within a pair
EDGE_TYPES = SELF_EDGE_TYPES + (LINE_EDGE,)  # the edge types of a built pair graph

# Node attributes.
KPTS0 = "kpts0"
KPTS1 = "kpts1"
POS0 = "pos0"
POS1 = "pos1"
PATCH0 = "patch0"
PATCH1 = "patch1"
SCORE = "score"
LINE_FEAT = "line_feat"

# Edge attributes.
EDGE_INDEX = "edge_index"
DENSE = "dense"  # marker of an implicit complete edge type, one bool per graph

# Graph attributes.
IMAGE_SIZE0 = "image_size0"
IMAGE_SIZE1 = "image_size1"
K0 = "K0"
K1 = "K1"
T_0TO1 = "T_0to1"
PAIR_ID = "pair_id"  # str, collates to a list: e.g. "kitti/06/000010-000011"
SUBSET = "subset"  # str: dataset subset (e.g. "mvs", "sun3d", "kitti/06") for per-subset tables
SWAPPED = "swapped"  # [1] bool, set by swap_images / RandomSwap: images 0 and 1 exchanged
ROLL = "roll"  # [1] float64, set by roll_cameras / RandomRoll: the cameras' roll (radians)
IMAGE0 = "image0"  # [1, C, H, W] float in [0, 1], only with keep_images=True
IMAGE1 = "image1"

__all__ = [n for n in dir() if n.isupper()]
