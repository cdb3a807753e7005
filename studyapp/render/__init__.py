"""The skinned-mesh viewer: what participants see.

Modules, each with one job:

* ``avatar``   -- the :class:`Avatar` data model and the procedurally built default avatar (T-pose, 52 ARKit morphs)
* ``gltf``     -- glTF 2.0 / GLB / VRM import and GLB export
* ``pose``     -- motion (any skeleton) + face animation -> per-frame palettes and morph weights (:class:`SlotAnimation`)
* ``camera``   -- camera matrices and the framing shared by all slots
* ``scene``    -- :class:`TrialScene` (three slots, one camera, neutral labels) and ``build_trial_scene``
* ``gpu``      -- thin wrappers for GPU resources (mesh buffers, morph textures, palette buffers, labels)
* ``renderer`` -- :class:`Renderer`: draws a scene into any framebuffer (GPU skinning + morphs, studio light)
* ``context``  -- headless contexts, :class:`OffscreenTarget` and the GLFW :class:`Window`
* ``video``    -- MP4 (H.264 + AAC) and PNG output
* ``cli``      -- ``studyapp view`` and ``studyapp render``
"""
