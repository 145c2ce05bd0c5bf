"""Media files and devices, below everything that makes them: the MP4 writer (:mod:`~robogest.media.video`), the PNG
writer (:mod:`~robogest.media.png`) and the speech audio output (:mod:`~robogest.media.audio`). Nothing here knows of
robots, simulators or servos; the simulator renders the frames and the player schedules the audio."""
