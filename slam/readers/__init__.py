"""Reading recorded runs (ROS bags, CARMEN, BROAD, libRSF, run folders) into a Recording, checked against physics."""
