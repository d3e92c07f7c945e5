"""Contact: node-to-surface between deformable bodies (:mod:`.node_to_surface`), rigid
analytic obstacles (:mod:`.rigid`), nodal rigid-wall contact with friction
(:mod:`.rigid_wall`) and the ipctk barrier for self-contact (:mod:`.ipc`)."""
