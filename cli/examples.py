"""The examples of each command's ``--help``."""

EXAMPLES = {
    "optimize": """examples:
  posegraph generate sphere sphere.g2o
  posegraph optimize sphere.g2o -o optimised.g2o --plot optimised.png
  posegraph optimize sphere.g2o -o poses.txt --to kitti --init odometry --max-iterations 50 --json
  posegraph optimize sphere.g2o -o fixed.g2o --fix 0 17 --covariances covariances.txt
  posegraph generate manhattan manhattan.g2o
  posegraph generate false-loops false_loops.g2o --from manhattan.g2o --fraction 0.2
  posegraph optimize false_loops.g2o -o inliers.g2o --robust gnc --drop-rejected --plot gnc.png""",
    "info": """examples:
  posegraph generate manhattan manhattan.g2o
  posegraph info manhattan.g2o
  posegraph generate false-loops false_loops.g2o --from manhattan.g2o --fraction 0.2
  posegraph info false_loops.g2o --json""",
    "convert": """examples:
  posegraph generate sphere sphere.g2o --truth truth.tum
  posegraph convert sphere.g2o sphere.graph         # g2o -> TORO
  posegraph convert sphere.g2o poses.tum            # poses as TUM: id tx ty tz qx qy qz qw
  posegraph convert sphere.g2o poses.txt --to kitti
  posegraph convert truth.tum odometry.g2o --sigmas 0.05 0.01  # a trajectory -> odometry graph""",
    "plot": """examples:
  posegraph generate sphere sphere.g2o --truth truth.tum
  posegraph optimize sphere.g2o -o optimised.g2o
  posegraph plot sphere.g2o optimised.g2o -o overlay.png
  posegraph plot optimised.g2o truth.tum -o top.png --view top""",
    "eval": """examples:
  posegraph generate sphere sphere.g2o --truth truth.tum
  posegraph optimize sphere.g2o -o optimised.g2o
  posegraph eval optimised.g2o truth.tum --plot ate.png --plot-colormap-max 0.5
  posegraph eval optimised.g2o truth.tum --align sim3 --json
  posegraph convert optimised.g2o estimate.kitti
  posegraph convert truth.tum truth.kitti
  posegraph eval estimate.kitti truth.kitti --delta 10""",
    "scale-drift": """examples:
  posegraph generate monocular monocular.g2o --truth groundtruth.tum
  posegraph scale-drift monocular.g2o -o corrected.tum --gt groundtruth.tum --plot drift.png
  posegraph scale-drift monocular.g2o -o corrected.txt --to kitti --convention camera_from_world
  posegraph generate false-loops place_recognition.g2o --from monocular.g2o --fraction 0.1
  posegraph scale-drift place_recognition.g2o -o corrected.g2o --robust gnc --json""",
    "certify": """examples:
  posegraph generate grid grid.g2o --size 3
  posegraph certify grid.g2o
  posegraph certify grid.g2o --init odometry --json""",
    "bench": """examples:
  posegraph datasets download tinyGrid3D smallGrid3D
  posegraph bench --graphs tinyGrid3D smallGrid3D --repeats 3
  posegraph bench --graphs tinyGrid3D --solver dogleg --json""",
    "generate": """examples:
  posegraph generate sphere sphere.g2o --truth sphere_truth.tum
  posegraph generate grid grid.g2o --size 4 --seed 3
  posegraph generate manhattan manhattan.g2o --poses 500 --truth manhattan_truth.tum
  posegraph generate monocular monocular.g2o --truth monocular_truth.tum --drift 0.02
  posegraph generate false-loops false_loops.g2o --from manhattan.g2o --fraction 0.2""",
    "datasets": """examples:
  posegraph datasets list
  posegraph datasets download intel sphere2500
  posegraph datasets download tinyGrid3D --to benchmark_graphs""",
}
"""Each command's ``--help`` examples; each set runs as written, in order, in an empty folder
(``tests/cli/test_examples.py``)."""
